"""The sim node: an rclpy shell, and its ROS-free core (parameters, messages, the cycle)."""
