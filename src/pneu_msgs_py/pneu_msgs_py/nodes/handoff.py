"""Publishing off the 1 kHz critical path: the loop hands its messages to a thread of their own.

In the one-process deployment the loop's tick is: sample in, every controller's answer,
commands out -- the topics (the sample, the commands, the controller states) are for
monitoring and bags, not for the loop. :class:`Handoff` takes them from the loop thread
without waiting for anything: :meth:`Handoff.put` appends one tick's batch of
``(publish, payload)`` pairs to a bounded queue and writes one byte to a pipe; the
publishing thread, blocked in ``os.read`` (the GIL released), wakes and calls each
``publish(payload)`` in order. When ``depth`` batches are waiting -- a publisher stuck in the
middleware, a consumer that fell behind -- the oldest batch is dropped and counted
(:attr:`Handoff.dropped`): monitoring data is lost before a tick is ever delayed.

ROS-free (the publish functions are whatever the node hands in): tested without rclpy.
"""

from __future__ import annotations

import collections
import os
import threading
from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["Batch", "Handoff"]

#: one tick's messages: (publish function, its one argument), published in this order
Batch = Sequence[tuple[Callable[[Any], Any], Any]]


class Handoff:
    """A bounded hand-off from the loop thread to a publishing thread (module docstring).

    ``depth``: batches that may wait (one per tick: 200 = 0.2 s at 1 kHz). ``on_error``
    receives an exception a publish function raised (the thread goes on). Start with
    :meth:`start`; :meth:`close` publishes what is queued (up to ``timeout_s``) and stops.
    """

    def __init__(
        self,
        depth: int = 200,
        name: str = "pneu_publisher",
        on_error: Callable[[BaseException], None] | None = None,
    ) -> None:
        if depth < 1:
            raise ValueError(f"depth: {depth!r} refused; allowed: an integer >= 1")
        self.depth = int(depth)
        self.name = name
        self.on_error = on_error
        self.dropped = 0  # batches dropped by put() (the loop thread's count)
        self.published = 0  # batches published (the publishing thread's count)
        self.errors = 0
        self._queue: collections.deque = collections.deque()
        self._r, self._w = os.pipe()
        os.set_blocking(self._w, False)
        self._closing = False
        self._closed = False
        self._thread: threading.Thread | None = None

    # -- the loop thread -------------------------------------------------------
    def put(self, batch: Batch) -> None:
        """Queue one tick's batch; never blocks (the oldest batch goes when ``depth`` wait)."""
        q = self._queue
        while len(q) >= self.depth:
            try:
                q.popleft()
            except IndexError:  # the publishing thread took it meanwhile
                break
            self.dropped += 1
        q.append(batch)
        try:
            os.write(self._w, b"\0")
        except (BlockingIOError, OSError):  # the pipe is full (the thread is awake) or closed
            pass

    # -- the publishing thread ---------------------------------------------------
    def start(self) -> threading.Thread:
        """Start the publishing thread (it inherits the starting thread's scheduling)."""
        self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
        self._thread.start()
        return self._thread

    def _run(self) -> None:
        q = self._queue
        while True:
            try:
                woke = os.read(self._r, 4096)
            except OSError:
                return
            while q:
                try:
                    batch = q.popleft()
                except IndexError:
                    break
                for publish, payload in batch:
                    try:
                        publish(payload)
                    except Exception as err:  # a publisher gone at shutdown, say
                        self.errors += 1
                        if self.on_error is not None:
                            self.on_error(err)
                self.published += 1
            if self._closing or not woke:
                return

    def pending(self) -> int:
        """Batches waiting now."""
        return len(self._queue)

    def close(self, timeout_s: float = 2.0) -> None:
        """Publish what is queued (up to ``timeout_s``), stop the thread (once). Only the pipe's
        read end is closed here: a late :meth:`put` from a loop still ending then fails on its
        own write end (EPIPE, ignored) instead of writing into a file that reused the number."""
        if self._closed:
            return
        self._closed = self._closing = True
        try:
            os.write(self._w, b"\0")
        except OSError:
            pass
        if self._thread is not None:
            self._thread.join(timeout_s)
        if self._thread is None or not self._thread.is_alive():
            os.close(self._r)

    def __del__(self) -> None:
        try:
            os.close(self._w)
        except (OSError, AttributeError):
            pass

    def counters(self) -> dict[str, str]:
        """For ``/diagnostics``: batches published, dropped and failed."""
        return {
            "published_batches": str(self.published),
            "dropped_batches": str(self.dropped),
            "publish_errors": str(self.errors),
        }
