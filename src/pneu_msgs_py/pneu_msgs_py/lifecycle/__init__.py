"""The life of a command and its outputs: exit codes, signals, output claims, the duration cap.

- :mod:`.exits` -- the documented exit codes (0, 1, 2, 3, 129, 130, 143);
- :mod:`.signals` -- SIGINT, SIGTERM and SIGHUP as a clean interruption, raised at
  once where nothing is being written, recorded and polled where it is;
- :mod:`.outputs` -- an output directory or file claimed before anything is
  written (refused when non-empty unless ``--overwrite``, locked against a
  second writer, never one of the inputs), written under ``.partial`` names
  and renamed when complete;
- :mod:`.duration` -- the one duration cap of every command;
- :mod:`.realtime` -- what a 1 kHz process asks of the OS (SCHED_FIFO, locked memory,
  timer slack), what it could not get and what that costs, in one line.
"""
