"""``pneu sim``: open-loop runs of the twin."""
