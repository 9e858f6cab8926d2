"""Exit codes of every ``pneu`` command (docs/cli.md's table is checked against :data:`EXIT_CODES`)."""

from __future__ import annotations

import signal

__all__ = [
    "BAD_INPUT",
    "CommandFailed",
    "EXIT_CODES",
    "OK",
    "RUNTIME_ERROR",
    "SAFETY_STOP",
    "interrupted_code",
]

OK = 0
RUNTIME_ERROR = 1  # the command failed while running (disk full, an internal error)
BAD_INPUT = 2  # an argument, a config file or an input bag refused before anything was written
SAFETY_STOP = 3  # the run completed, but the supervisor took an axis safe (or detected a fault)


class CommandFailed(RuntimeError):
    """The command failed while running for a reason its message says in one line (exit 1,
    :data:`RUNTIME_ERROR`; not an internal error): a lost worker, a cluster that went away."""


def interrupted_code(signum: int) -> int:
    """128 + the signal number, as a shell reports a process ended by that signal."""
    return 128 + int(signum)


EXIT_CODES: tuple[tuple[int, str], ...] = (
    (OK, "success"),
    (
        RUNTIME_ERROR,
        "runtime error: the command failed while running (e.g. disk full); one line says why",
    ),
    (
        BAD_INPUT,
        "bad input: an argument, a config file, an input bag or the output location was refused, "
        "before anything was written; one line names the field and what is allowed",
    ),
    (
        SAFETY_STOP,
        "the run completed, but the safety supervisor took an axis safe or detected a fault "
        "(pneu run; the bag and metrics.json say which rule and when)",
    ),
    (
        interrupted_code(signal.SIGHUP),
        "interrupted by SIGHUP (terminal closed): outputs finished, marked interrupted",
    ),
    (
        interrupted_code(signal.SIGINT),
        "interrupted by SIGINT (Ctrl-C): outputs finished, marked interrupted",
    ),
    (
        interrupted_code(signal.SIGTERM),
        "interrupted by SIGTERM: outputs finished, marked interrupted",
    ),
)
