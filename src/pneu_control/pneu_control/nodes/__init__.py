"""rclpy shells (controller and logger nodes) and their ROS-free per-sample cores."""

from pneu_msgs_py.nodes.run import node_entry

# console scripts: the node module imported under a Ctrl-C guard (node_entry)
linear_controller = node_entry("pneu_control.nodes.controller_node", "main_linear")
rotary_controller = node_entry("pneu_control.nodes.controller_node", "main_rotary")
logger = node_entry("pneu_control.nodes.logger_node", "main")
controller_manager = node_entry("pneu_control.nodes.controller_manager", "main")
exciter = node_entry("pneu_control.nodes.exciter_node", "main")
task_runner = node_entry("pneu_control.nodes.task_node", "main")
