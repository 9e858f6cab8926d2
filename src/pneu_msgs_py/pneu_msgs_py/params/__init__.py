"""The parameter framework: one frozen dataclass per group, validation, YAML, ROS descriptors."""
