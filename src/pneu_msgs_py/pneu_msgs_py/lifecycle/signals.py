"""SIGINT, SIGTERM and SIGHUP as one clean interruption, whatever the command is doing.

:func:`install` (the ``pneu`` command's first act) makes the three signals
raise :class:`Interrupted` -- at once while nothing is being written. Code
that writes an output wraps that in :func:`deferred`: a signal arriving
there is only recorded, and the code polls :func:`pending` at safe points
(the runner once per control cycle), stops, finishes its files (marked
interrupted) and returns; the command then exits with 128 + the signal
number (:func:`pneu_msgs_py.lifecycle.exits.interrupted_code`). A second
signal during finalisation is recorded too, never half-way through a file.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Callable, Iterator

__all__ = [
    "SIGNALS",
    "Interrupted",
    "deferred",
    "install",
    "pending",
    "pending_since",
    "raise_if_pending",
    "signal_name",
]

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def signal_name(signum: int) -> str:
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


class Interrupted(KeyboardInterrupt):
    """The command was interrupted by ``signum`` (a KeyboardInterrupt, so Ctrl-C code handles it)."""

    def __init__(self, signum: int) -> None:
        self.signum = int(signum)
        super().__init__(signal_name(signum))


class _State:
    __slots__ = ("defer", "pending", "utc")

    def __init__(self) -> None:
        self.pending: int | None = None  # the first signal received
        self.utc: str = ""  # when it came (UTC, ISO 8601)
        self.defer = 0  # depth of deferred() blocks


STATE = _State()


def _handler(signum: int, _frame: object) -> None:
    if STATE.pending is None:
        STATE.pending = signum
        STATE.utc = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    if STATE.defer == 0:
        raise Interrupted(signum)


def install() -> Callable[[], None]:
    """Handle SIGINT, SIGTERM and SIGHUP (main thread only); returns a function restoring the old handlers."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    STATE.pending, STATE.utc, STATE.defer = None, "", 0
    old = {s: signal.signal(s, _handler) for s in SIGNALS}

    def restore() -> None:
        for s, h in old.items():
            signal.signal(s, h)

    return restore


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Inside, a signal is only recorded (poll :func:`pending`); outside, it raises at once."""
    STATE.defer += 1
    try:
        yield
    finally:
        STATE.defer -= 1


def pending() -> int | None:
    """The signal received since :func:`install` (None if none)."""
    return STATE.pending


def pending_since() -> str:
    """UTC time (ISO 8601) the pending signal arrived, or ``""``."""
    return STATE.utc


def raise_if_pending() -> None:
    """Raise :class:`Interrupted` if a signal was recorded (a safe point outside any file)."""
    if STATE.pending is not None:
        raise Interrupted(STATE.pending)
