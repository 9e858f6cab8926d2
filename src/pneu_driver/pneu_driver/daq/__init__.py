"""The DAQ: rig parameters, channel scaling, the backend protocol, the NI-DAQmx backend, errors."""
