"""Benchmarks of the driver loop (timed by ``pneu bench``, never by tests)."""
