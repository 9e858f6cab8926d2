"""The control cycle of DESIGN §3 on the twin (plant, faults, supervisor), written once."""
