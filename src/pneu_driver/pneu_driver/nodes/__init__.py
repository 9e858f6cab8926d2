"""The driver node: an rclpy shell around the driver loop."""
