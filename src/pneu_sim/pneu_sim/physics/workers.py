"""The replay's worker threads: one pool, the size of the machine, for every compiled replay.

The replay kernels (:mod:`pneu_sim.physics.replay`) are compiled without the GIL,
so plain Python threads run them side by side. Every caller shares one pool of
:func:`size` threads -- a fit's residuals (its segments split over the pool), the
columns of its Jacobian (one column a task), the two axes fitted at once
(:func:`concurrently`) -- so the cores are kept busy by whatever is ready, and
never oversubscribed by replays.

Two rules keep it simple:

- a task running on a pool thread never waits on the pool: what it replays it
  replays itself (:func:`in_worker`), so the pool cannot deadlock;
- results do not depend on the scheduling: each task writes its own rows or
  returns its own value, in the caller's order.

Work started by :func:`concurrently` (or a :class:`Group`) is called off as a whole -- when one of its
tasks fails, or the caller is interrupted (Ctrl-C) -- at the next replay any of its
threads starts (:class:`Cancelled`), so an interrupted command ends within a
replay, not after the work.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from typing import Any

__all__ = ["Cancelled", "Group", "concurrently", "in_worker", "map_tasks", "run_all", "size"]

_LOCK = threading.Lock()
_POOL: ThreadPoolExecutor | None = None
_LOCAL = threading.local()


class Cancelled(Exception):
    """The work was called off: another task of the same :func:`concurrently` failed, or its
    caller was interrupted."""


def size() -> int:
    """Threads in the pool: numba's thread count (the machine's cores, or
    ``NUMBA_NUM_THREADS``)."""
    from numba import config

    return max(1, int(config.NUMBA_NUM_THREADS))


def in_worker() -> bool:
    """Is the calling thread one of the pool's?"""
    return getattr(_LOCAL, "worker", False)


def _mark() -> None:
    _LOCAL.worker = True


def _pool() -> ThreadPoolExecutor:
    global _POOL
    with _LOCK:
        if _POOL is None:
            _POOL = ThreadPoolExecutor(
                max_workers=size(), thread_name_prefix="pneu-replay", initializer=_mark
            )
        return _POOL


def _events() -> tuple[threading.Event, ...]:
    """The cancel events of the :func:`concurrently` calls the calling thread works for."""
    return getattr(_LOCAL, "cancel", ())


def _check(events: tuple[threading.Event, ...]) -> None:
    if any(e.is_set() for e in events):
        raise Cancelled("called off")


def _on_pool(events: tuple[threading.Event, ...], task: Callable[[], Any]) -> Any:
    _check(events)
    return task()


def run_all(tasks: list[Callable[[], Any]]) -> list[Any]:
    """Each of ``tasks`` called once; their results in order. On the pool unless there is
    one task, one thread, or the caller is itself a pool thread (then in turn, here).
    Raises :class:`Cancelled` if the caller's work was called off."""
    events = _events()
    _check(events)
    if len(tasks) <= 1 or size() == 1 or in_worker():
        return [t() for t in tasks]
    futures = [_pool().submit(_on_pool, events, t) for t in tasks]
    return [f.result() for f in futures]


def map_tasks(fn: Callable[[Any], Any], items: Iterable[Any]) -> list[Any]:
    """``[fn(x) for x in items]`` on the pool (:func:`run_all`); a ``workers=`` map for
    scipy's finite differences."""
    return run_all([lambda x=x: fn(x) for x in items])


class Group:
    """Threads started as their work becomes ready (:meth:`start`), joined at the end
    (:meth:`results`); the first failure calls the rest off and is raised, and so is an
    interruption of the caller (Ctrl-C) -- leaving the ``with`` block waits until every thread
    has stopped, which each does at its next replay."""

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._chain = (*_events(), self._stop)
        self._ex = ThreadPoolExecutor(thread_name_prefix="pneu-task", max_workers=64)
        self._futures: list = []

    def __enter__(self) -> Group:
        return self

    def __exit__(self, kind, _value, _tb) -> None:
        if kind is not None:
            self._stop.set()
        self._ex.shutdown(wait=True)

    def start(self, tasks: list[Callable[[], Any]]) -> None:
        """Each of ``tasks`` on a thread of its own, now (its replays on the pool)."""
        _check(self._chain)

        def run(task: Callable[[], Any]) -> Any:
            _LOCAL.cancel = self._chain
            return task()

        self._futures.extend(self._ex.submit(run, t) for t in tasks)

    def results(self) -> list[Any]:
        """Every started task's result, in the order started."""
        wait(self._futures, return_when=FIRST_EXCEPTION)
        failed = [f for f in self._futures if f.done() and f.exception() is not None]
        if failed:
            self._stop.set()
            wait(self._futures)
            firsts = [f.exception() for f in failed if not isinstance(f.exception(), Cancelled)]
            raise (firsts or [failed[0].exception()])[0]
        return [f.result() for f in self._futures]


def concurrently(tasks: list[Callable[[], Any]]) -> list[Any]:
    """Each of ``tasks`` on a thread of its own (their replays on the pool), their results
    in order (:class:`Group`)."""
    if len(tasks) <= 1:
        return [t() for t in tasks]
    with Group() as group:
        group.start(tasks)
        return group.results()
