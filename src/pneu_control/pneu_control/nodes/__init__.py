"""rclpy shells (controller and logger nodes) and their ROS-free per-sample cores."""
