"""Benchmarks of the bag writer and reader (timed by ``pneu bench``, never by tests)."""
