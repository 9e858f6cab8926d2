"""Node plumbing every package shares: one node main (:mod:`.run`), the launch-file helper (:mod:`.launch_graph`)."""
