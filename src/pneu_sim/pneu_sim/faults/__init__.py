"""Injected faults (sensors, valves, plant, controllers) for tests and rehearsal."""
