"""The safety supervisor shared by the runner, the sim node and the driver, and its parameters."""
