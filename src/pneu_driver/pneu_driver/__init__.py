"""pneu_driver: the rig's DAQ driver cores (no rclpy; nidaqmx only inside ``nidaqmx_backend``).

- :mod:`~pneu_driver.daq.rig` -- ``RigParams`` (``config/rig.yaml``): device, channels, scaling, loop;
- :mod:`~pneu_driver.daq.scaling` -- volts/counts ↔ SI, the AO clamp, ``RawSample``;
- :mod:`~pneu_driver.safety.supervisor` -- ``SafetySupervisor`` and ``SafetyParams`` (``config/safety.yaml``);
- :mod:`~pneu_driver.daq.backend` -- the ``DaqBackend`` protocol and ``SimBackend`` (any plant as a DAQ);
- :mod:`~pneu_driver.daq.nidaqmx_backend` -- ``NidaqmxBackend``: the PCI-6221, HW-timed single point;
- :mod:`~pneu_driver.loop.driver_loop` -- ``DriverLoop``: the 1 kHz read → publish → command → write cycle;
- :mod:`~pneu_driver.bench.loop` -- ``loop_pacing()``; :mod:`~pneu_driver.cli.probe` -- is the DAQ there?
"""

__version__ = "0.1.0"
