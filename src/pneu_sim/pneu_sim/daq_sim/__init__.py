"""The simulated DAQ: the twin behind the driver's backend interface, outputs that outlive the process.

- :mod:`.card` -- ``CardRegister``: the simulated card's AO and heartbeat DO state (file-backed);
- :mod:`.backend` -- ``TwinDaq`` (``backend: sim``): volts in, volts and counts out, one sample clock.
"""
