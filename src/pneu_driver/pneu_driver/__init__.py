"""pneu_driver: the rig's DAQ driver (no rclpy outside ``nodes/``; nidaqmx only in the backend).

- :mod:`~pneu_driver.daq` -- ``RigParams`` (``config/rig.yaml``), volts/counts ↔ SI, the
  ``DaqBackend`` protocol, ``NidaqmxBackend`` (the PCI-6221) and ``SimBackend``;
- :mod:`~pneu_driver.loop` -- ``DriverLoop``: the 1 kHz read → check → publish → command → write cycle;
- :mod:`~pneu_driver.safety` -- ``SafetySupervisor`` and ``SafetyParams`` (``config/safety.yaml``);
- :mod:`~pneu_driver.nodes` -- the driver node; :mod:`~pneu_driver.cli.probe` -- is the DAQ there?
"""

__version__ = "0.1.0"
