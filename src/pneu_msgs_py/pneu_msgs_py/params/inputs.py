"""The files a command reads: each a regular file of bounded size, remembered so no output replaces it.

- :func:`read_input` reads a text input (a config file, a waypoint table, a task):
  a regular file only (a device such as ``/dev/zero`` would never end, a pipe
  without a writer would block), at most :data:`MAX_TEXT_BYTES`; anything else is
  refused with one line (:class:`UnreadableInput`, turned into the caller's error).
- :func:`note_input` remembers a file the command read (bags note theirs too);
  :func:`is_input` answers whether a path is one of them, by the file's identity
  (device and inode: a link or another spelling of the path is the same file).
  The output claims (:mod:`pneu_msgs_py.lifecycle.outputs`) refuse to replace or remove any of them, so
  ``--overwrite`` never deletes an input, whichever option named it.

The record is kept only while a command runs (:func:`tracking`, entered by
``pneu``'s ``main``); outside it :func:`note_input` forgets at once.
"""

from __future__ import annotations

import contextlib
import os
import stat
from collections.abc import Iterator
from pathlib import Path

__all__ = [
    "MAX_TEXT_BYTES",
    "UnreadableInput",
    "is_input",
    "note_input",
    "read_input",
    "tracking",
]

# a config file is a few kB, a waypoint table of the longest run (600 s at 1 kHz) ~15 MB
MAX_TEXT_BYTES = 64 * 2**20

_READ: dict[tuple[int, int], str] | None = None  # (st_dev, st_ino) -> the path as given


class UnreadableInput(Exception):
    """A text input that is not a readable regular file of bounded size; ``problem`` says why."""

    def __init__(self, path: str | os.PathLike, problem: str):
        self.path, self.problem = str(path), problem
        super().__init__(f"{path}: {problem}")


@contextlib.contextmanager
def tracking() -> Iterator[None]:
    """Remember the inputs read inside (one command's life)."""
    global _READ
    saved, _READ = _READ, {}
    try:
        yield
    finally:
        _READ = saved


def _identity(st: os.stat_result) -> tuple[int, int]:
    return (st.st_dev, st.st_ino)


def note_input(path: str | os.PathLike, st: os.stat_result | None = None) -> None:
    """Remember ``path`` as an input of the running command (no-op outside :func:`tracking`)."""
    if _READ is None:
        return
    try:
        st = st if st is not None else os.stat(path)
    except OSError:
        return
    _READ.setdefault(_identity(st), str(path))


def is_input(path: str | os.PathLike) -> str | None:
    """The input ``path`` is (as it was named when read), or None."""
    if not _READ:
        return None
    try:
        return _READ.get(_identity(os.stat(path)))
    except OSError:
        return None


def read_input(path: str | os.PathLike, max_bytes: int = MAX_TEXT_BYTES) -> bytes:
    """The bytes of a regular file of at most ``max_bytes``, noted as an input; else
    :class:`UnreadableInput`."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except IsADirectoryError:
        raise UnreadableInput(path, "is a directory, not a file") from None
    except OSError as err:
        raise UnreadableInput(path, f"cannot read: {err.strerror or err}") from None
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
        os.close(fd)
        if stat.S_ISDIR(st.st_mode):
            raise UnreadableInput(path, "is a directory, not a file")
        raise UnreadableInput(path, "not a regular file (a device, pipe or socket)")
    with os.fdopen(fd, "rb") as fh:
        if st.st_size > max_bytes:
            raise UnreadableInput(
                path, f"{st.st_size} bytes; allowed: at most {max_bytes} bytes for this input"
            )
        try:
            data = fh.read(max_bytes + 1)
        except OSError as err:
            raise UnreadableInput(path, f"cannot read: {err.strerror or err}") from None
    if len(data) > max_bytes:  # grew while read
        raise UnreadableInput(path, f"more than {max_bytes} bytes; allowed: at most that")
    note_input(Path(path), st)
    return data
