"""One driver per card: a host-wide lock on the device a backend drives.

Two drivers on one PCI-6221 would write both valves from two loops (NI-DAQmx itself
refuses the second process's tasks only once they start, with -50103 "resource
reserved", after its first writes). :func:`device_claim` takes a lock file named after
the device (``/run/lock``, else the temporary directory) for the life of the loop; a
second driver -- another graph on this host, on any ROS domain -- is refused in one line
naming the holder's pid, before it touches the card.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import tempfile
from collections.abc import Iterator
from pathlib import Path

from filelock import FileLock, Timeout

from pneu_driver.daq.errors import DriverError

__all__ = ["DeviceInUseError", "device_claim", "lock_path"]


class DeviceInUseError(DriverError):
    """Another driver holds the device."""


def lock_path(device: str) -> Path:
    """The lock file of ``device`` (a DAQ name such as ``Dev1``, or a simulated card's path)."""
    base = Path("/run/lock") if os.access("/run/lock", os.W_OK) else Path(tempfile.gettempdir())
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", device)[-60:]
    digest = hashlib.sha256(device.encode()).hexdigest()[:12]
    return base / f"pneu-daq-{safe}-{digest}.lock"


@contextlib.contextmanager
def device_claim(device: str | None) -> Iterator[None]:
    """Hold ``device`` for the block (None: a backend that drives nothing shared)."""
    if device is None:
        yield
        return
    path = lock_path(device)
    owner = path.with_suffix(".pid")
    lock = FileLock(str(path), is_singleton=False)
    try:
        lock.acquire(timeout=0)
    except Timeout:
        try:
            pid = owner.read_text().strip() or "?"
        except OSError:
            pid = "?"
        raise DeviceInUseError(
            f"device {device}: in use by another pneu driver (pid {pid}); one driver per card "
            f"(lock {path})"
        ) from None
    try:
        owner.write_text(str(os.getpid()))
        yield
    finally:
        with contextlib.suppress(OSError):
            owner.unlink()
        lock.release()
