"""Benchmarks of the controller cores (timed by ``pneu bench``, never by tests)."""
