"""Driver commands without ROS: ``python -m pneu_driver.cli.probe`` (is the DAQ there?)."""
