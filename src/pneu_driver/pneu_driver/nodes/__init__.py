"""The driver node: an rclpy shell around the driver loop."""

from pneu_msgs_py.nodes.run import node_entry

# console scripts: the node module imported under a Ctrl-C guard (node_entry)
driver_node = node_entry("pneu_driver.nodes.driver_node", "main")
