"""Experiments on the twin: the in-process runner, sessions, the paper's table, tuning, replay, faults."""
