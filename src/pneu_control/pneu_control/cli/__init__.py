"""The ``pneu`` command: one module per subcommand, dispatched by :mod:`.main`."""
