"""Progress bars for the long commands (``pneu paper``, ``tune``, and any command that loops).

A bar on stderr with the count, the rate and the time left (``tqdm``); it
draws only when stderr is a terminal (``disable=None``), so logs, pipes, CI
and tests get nothing but the command's own lines. Lines printed while a bar
is up go through :meth:`Bar.write` so the bar is redrawn below them.

    bar = progress_bar(total=len(points), desc="tune linear", unit="point")
    score = counted(score, bar)  # one step per call
    ...
    bar.write("linear pid: ...")
    bar.close()

``TQDM_DISABLE=1`` turns bars off on a terminal too (tqdm reads ``TQDM_*`` defaults).
"""

from __future__ import annotations

import functools
import sys
import time
from collections.abc import Callable
from typing import Any, TextIO, TypeVar

from tqdm import tqdm

__all__ = ["Bar", "counted", "progress_bar", "progress_to"]

Bar = tqdm
F = TypeVar("F", bound=Callable[..., Any])


def progress_bar(total: int, desc: str, *, unit: str = "run", file: TextIO | None = None) -> Bar:
    """A progress bar of ``total`` steps on ``file`` (default stderr), silent off a terminal."""
    return tqdm(
        total=total,
        desc=desc,
        unit=unit,
        file=sys.stderr if file is None else file,
        disable=None,  # None: off when the file is not a TTY
        dynamic_ncols=True,
        leave=True,
        smoothing=0.1,  # runs differ in length: a long memory gives a steadier time left
    )


def counted(fn: F, bar: Bar) -> F:
    """``fn`` advancing ``bar`` by one step after each call."""

    @functools.wraps(fn)
    def step(*args: Any, **kwargs: Any) -> Any:
        out = fn(*args, **kwargs)
        bar.update(1)
        return out

    return step  # type: ignore[return-value]


def progress_to(
    bar: Bar, label: str, *, unit: str = "run", every_s: float = 10.0
) -> Callable[[int, int], None]:
    """A ``progress(done, total)`` callback (sweeps, identification stages) that moves ``bar``
    to ``done``; off a terminal (no bar drawn) one line ``label: done/total, N s`` at most
    every ``every_s`` seconds and at the end, so a log still shows the work advancing."""
    start = time.monotonic()
    last = [start]

    def report(done: int, total: int) -> None:
        if bar.total != total:
            bar.total = total
        bar.update(done - bar.n)
        now = time.monotonic()
        if bar.disable and (done == total or now - last[0] >= every_s):
            last[0] = now
            print(f"  {label}: {done}/{total} {unit}s, {now - start:.0f} s", file=sys.stderr)

    return report
