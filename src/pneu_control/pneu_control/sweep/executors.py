"""Where a sweep's runs execute: this process, local processes, or a Dask cluster.

Every executor maps one picklable task function over the tasks and returns the
results in task order, whatever order they finished in; each run is
deterministic and single-threaded, so the table is the same bytes on any
executor (tested).

- ``serial``: in this process, one after the other.
- ``local`` (default): :class:`concurrent.futures.ProcessPoolExecutor` with the
  ``spawn`` start method (no fork of a process that may hold threads), one
  worker per available core.
- ``dask``: :mod:`distributed` -- ``address`` (``tcp://host:8786``) names a
  running scheduler; without one a :class:`distributed.LocalCluster` (processes,
  one thread each, loopback only) is started for the sweep and shut down after.
  Workers must have the same pneu packages installed (the task function is sent
  by name, not by value); ``Client.get_versions(check=True)`` refuses a mismatch
  of Python or library versions first.

A task that hangs or a worker that dies never hangs the sweep: every wait has
a timeout (``timeout_s``, for the whole map).

An interruption (SIGINT, SIGTERM, SIGHUP: :class:`~pneu_msgs_py.lifecycle.signals.Interrupted`
raised in the waiting driver) leaves no worker behind: local workers ignore the
terminal's SIGINT (the driver decides) and are terminated and reaped, queued
runs cancelled; a local Dask cluster is closed (its nannies stop their workers);
on a remote cluster the sweep's futures are cancelled.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import Any

from pneu_msgs_py.lifecycle.exits import CommandFailed

__all__ = ["EXECUTORS", "SweepExecutorError", "default_workers", "map_tasks"]

EXECUTORS = ("local", "serial", "dask")
CONNECT_S = 10.0  # the wait for a Dask scheduler to accept the client


class SweepExecutorError(CommandFailed):
    """The executor could not run the sweep (timeout, lost worker, no cluster): exit 1, one line."""


def default_workers() -> int:
    """The CPUs this process may run on (all CPUs where affinity is unknown)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def map_tasks(
    fn: Callable[[Any], Any],
    tasks: Sequence[Any],
    *,
    executor: str = "local",
    workers: int | None = None,
    address: str | None = None,
    timeout_s: float = 24 * 3600.0,
    progress: Callable[[int, int], None] | None = None,
    client: Any | None = None,
) -> list[Any]:
    """``[fn(t) for t in tasks]``, on ``executor``; ``progress(done, total)`` as runs finish.

    ``client``: an existing :class:`distributed.Client` (``executor="dask"``), e.g. a
    test's in-process cluster; else one is made from ``address``.
    """
    if executor not in EXECUTORS:
        raise ValueError(f"executor: {executor!r} refused; allowed: one of {', '.join(EXECUTORS)}")
    if address is not None and executor != "dask":
        raise ValueError(f"address: {address!r} refused; allowed: only with executor dask")
    if workers is not None and workers < 1:
        raise ValueError(f"workers: {workers} refused; allowed: an integer >= 1")
    total = len(tasks)
    if executor == "serial" or total == 0:
        out = []
        for i, t in enumerate(tasks):
            out.append(fn(t))
            if progress is not None:
                progress(i + 1, total)
        return out
    if executor == "local":
        return _map_local(fn, tasks, workers or default_workers(), timeout_s, progress)
    return _map_dask(fn, tasks, workers, address, timeout_s, progress, client)


def _worker_init() -> None:
    """A local worker leaves SIGINT and SIGHUP to the driver (a terminal sends them to the
    whole process group); the driver stops it with SIGTERM."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)


def _stop_pool(pool: Any) -> None:
    """Cancel what is queued, terminate the workers and reap them (no process left behind)."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(timeout=5.0)
        if p.is_alive():
            p.kill()
            p.join(timeout=5.0)


def _map_local(fn, tasks, workers, timeout_s, progress) -> list[Any]:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures import TimeoutError as FuturesTimeout

    from pneu_msgs_py.lifecycle import signals

    out: list[Any] = [None] * len(tasks)
    ctx = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(
        max_workers=min(workers, len(tasks)), mp_context=ctx, initializer=_worker_init
    )
    try:
        futs = {pool.submit(fn, t): i for i, t in enumerate(tasks)}
        for n, fut in enumerate(as_completed(futs, timeout=timeout_s), start=1):
            out[futs[fut]] = fut.result()
            if progress is not None:
                progress(n, len(tasks))
    except FuturesTimeout:
        with signals.deferred():
            _stop_pool(pool)
        raise SweepExecutorError(f"sweep: runs not finished after {timeout_s:g} s") from None
    except BaseException:  # interrupted, or a run failed: stop the others now
        with signals.deferred():  # a second signal cannot cut the clean-up short
            _stop_pool(pool)
        raise
    pool.shutdown(wait=True)
    return out


def _map_dask(fn, tasks, workers, address, timeout_s, progress, client) -> list[Any]:
    try:
        import distributed
    except ImportError as err:  # an optional engine: say what to install
        raise SweepExecutorError(
            f"executor dask: {err}; install it with pip install distributed"
        ) from None

    if client is not None:
        return _gather(distributed, client, fn, tasks, timeout_s, progress)
    if address is not None:
        try:
            cl = distributed.Client(address, timeout=CONNECT_S)
        except (OSError, TimeoutError, ValueError) as err:
            raise SweepExecutorError(
                f"executor dask: no scheduler at {address} (within {CONNECT_S:g} s): {err}"
            ) from None
        except Exception as err:  # something answered, but not as a scheduler speaks
            raise SweepExecutorError(
                f"executor dask: {address} did not answer as a Dask scheduler "
                f"({type(err).__name__}: {str(err)[:120]})"
            ) from None
        with cl:
            try:
                cl.get_versions(check=True)
            except Exception as err:  # a version mismatch says which package, one line
                raise SweepExecutorError(
                    f"executor dask: {address}: {type(err).__name__}: {' '.join(str(err).split())[:300]}"
                ) from None
            return _gather(distributed, cl, fn, tasks, timeout_s, progress)
    from pneu_msgs_py.lifecycle import signals

    n = min(workers or default_workers(), len(tasks))
    cluster = distributed.LocalCluster(
        n_workers=n,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=None,
    )
    cl = None
    try:
        cl = distributed.Client(cluster)
        return _gather(distributed, cl, fn, tasks, timeout_s, progress)
    finally:
        with signals.deferred():  # closed whatever happened; a second signal waits
            if cl is not None:
                cl.close()
            cluster.close()


def _gather(distributed, client, fn, tasks, timeout_s, progress) -> list[Any]:
    # pure=False: every task runs, even two with equal arguments
    futs = client.map(fn, list(tasks), pure=False)
    index = {f.key: i for i, f in enumerate(futs)}
    out: list[Any] = [None] * len(tasks)
    try:
        done = distributed.as_completed(futs, timeout=timeout_s)
        for n, fut in enumerate(done, start=1):
            out[index[fut.key]] = fut.result(timeout=timeout_s)
            if progress is not None:
                progress(n, len(tasks))
    except TimeoutError:
        client.cancel(futs)
        raise SweepExecutorError(f"sweep: runs not finished after {timeout_s:g} s") from None
    except BaseException:  # interrupted: the sweep's runs are not left queued on the cluster
        from pneu_msgs_py.lifecycle import signals

        with signals.deferred():
            client.cancel(futs)
        raise
    return out
