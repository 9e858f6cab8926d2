"""The sim node: an rclpy shell, and its ROS-free core (parameters, messages, the cycle)."""

from pneu_msgs_py.nodes.run import node_entry

# console scripts: the node module imported under a Ctrl-C guard (node_entry)
sim_node = node_entry("pneu_sim.nodes.sim_node", "main")
