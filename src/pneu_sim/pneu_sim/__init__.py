"""pneu_sim: the physics twin of the rig, fault injection and the sim node."""
