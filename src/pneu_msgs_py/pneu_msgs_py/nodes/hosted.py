"""The one-process deployment's tick on the loop thread: controllers first, topics after.

The sim's and the driver's loop call :func:`answer_hosts` with each sample: every hosted
controller (``axis``, ``compute(sample) -> (u, messages)``) computes, its u goes to the
loop at once (``offer``), and the messages to publish -- the sample's, then each
controller's command and state -- are returned for the loop's
:class:`~pneu_msgs_py.nodes.handoff.Handoff`: nothing on the way from sample to command
waits for the middleware (DESIGN §10). ROS-free.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["answer_hosts"]


def answer_hosts(
    s: Any,
    hosts: tuple,
    crashed: dict[str, str],
    offer: Callable[[str, float], Any],
    log_error: Callable[[str], None],
) -> list:
    """Each hosted controller's answer to sample ``s`` offered (``offer(axis, u)``); returns
    their messages. A controller that raises falls silent from then on (``crashed[axis]``,
    one ``log_error`` line): the supervisor's command watchdog takes its axis safe."""
    out: list = []
    for h in hosts:
        if h.axis in crashed:
            continue
        try:
            u, messages = h.compute(s)
        except Exception as err:  # as the in-process runner: a crashed controller falls silent
            crashed[h.axis] = f"{type(err).__name__}: {err}"
            log_error(
                f"{h.axis} controller raised {crashed[h.axis]}; no more commands "
                "(the supervisor's watchdog takes the axis safe)"
            )
            continue
        offer(h.axis, u)
        out.extend(messages)
    return out
