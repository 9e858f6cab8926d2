"""Benchmarks of the plant (timed by ``pneu bench``, never by tests)."""
