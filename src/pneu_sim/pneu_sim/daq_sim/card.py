"""The simulated PCI-6221's output state: a register that outlives the process that drives it.

A real M Series card keeps driving its outputs when the program that set them
dies: the DACs hold their last value, a static DO line its last level. Only a
device reset, a driver reload or a power cycle changes them -- to 0 V on every
AO (NI-DAQmx "Initialized States for Terminals and Output Channels": M Series
AO reset to 0 V), which on an MPYE is a valve fully open, not closed.

:class:`CardRegister` is that state for the simulated card: two AO voltages,
the heartbeat DO level and its edge count, in a small file mapped with
``mmap`` (or anonymous memory for a run that needs no witness). Every write
lands in the mapping at once, so when the process is killed -- SIGKILL, a
crash, the OOM killer -- the file holds exactly what the card would be
driving, and another process (a test, ``read_card_state``, the next driver
start) can read it.

Layout (little-endian, 64 bytes): magic ``PNEUCARD``, version u32, DO level
u32, AO0 f64, AO1 f64 [V], DO edges u64, AO updates u64, clock tick u64,
pid i64 of the last process that wrote.
"""

from __future__ import annotations

import mmap
import os
import stat
import struct
from dataclasses import dataclass
from pathlib import Path

__all__ = ["CardRegister", "CardState", "read_card_state"]

_MAGIC = b"PNEUCARD"
_VERSION = 1
_LAYOUT = struct.Struct("<8sIIddQQQq")
_AO = struct.Struct("<dd")
_AO_AT = 16  # offset of AO0
_DO_AT = 12  # offset of the DO level
_EDGES_AT = 32  # DO edges, then AO updates, then the tick
_COUNTS = struct.Struct("<QQQ")
_U32 = struct.Struct("<I")
_PID = struct.Struct("<q")
_PID_AT = 56
SIZE = 64
POWER_UP_AO_V = 0.0  # M Series AO after power-up or a device reset


@dataclass(frozen=True)
class CardState:
    """What the card drives: AO voltages [V], the DO level, counters, the last writer's pid."""

    ao0_v: float
    ao1_v: float
    do_level: bool
    do_edges: int
    ao_updates: int
    tick: int
    pid: int


class CardRegister:
    """The card's output register, in ``path`` (created at power-up state) or anonymous memory.

    An existing file is the card as the last process left it (nothing resets a
    real card between two programs); only :meth:`reset_device` does.
    """

    def __init__(self, path: str | Path | None = None):
        self.path = Path(path) if path else None
        if self.path is None:
            self._mm = mmap.mmap(-1, SIZE)
            self._power_up()
            return
        self._refuse_foreign(self.path)
        if not self.path.exists():
            _create(self.path)
        fd = os.open(self.path, os.O_RDWR)
        try:
            fresh = os.fstat(fd).st_size != SIZE  # an empty file: a card never powered up
            if fresh:
                os.ftruncate(fd, SIZE)
            self._mm = mmap.mmap(fd, SIZE)
        finally:
            os.close(fd)
        magic, version = _LAYOUT.unpack_from(self._mm, 0)[:2]
        if fresh or magic != _MAGIC:
            self._power_up()
        elif version != _VERSION:
            raise ValueError(
                f"card file {self.path}: version {version} refused; allowed: {_VERSION} "
                "(delete the file: a new card powers up at 0 V)"
            )

    @staticmethod
    def _refuse_foreign(path: Path) -> None:
        """An existing file that is not a card register (another file of the user's, a bag,
        a device) is never truncated into one: refused with one line. An empty file is a
        card that never powered up."""
        from pneu_msgs_py.params.core import ParamError

        try:
            st = os.stat(path)
        except FileNotFoundError:
            return
        except OSError as err:
            raise ParamError(
                "backend sim card", str(path), f"a card file ({err.strerror})"
            ) from None
        why = ""
        if not stat.S_ISREG(st.st_mode):
            why = "not a regular file"
        elif st.st_size:
            with open(path, "rb") as fh:
                head = fh.read(_LAYOUT.size)
            if len(head) < _LAYOUT.size or _LAYOUT.unpack_from(head, 0)[0] != _MAGIC:
                why = "it holds something else"
        if why:
            raise ParamError(
                "backend sim card",
                str(path),
                f"a new file or the card file of an earlier run ({why}: never overwritten)",
            )
        from pneu_msgs_py.params.inputs import is_input

        if is_input(path):
            raise ParamError("backend sim card", str(path), "a file that is not an input")

    def _power_up(self) -> None:
        self._mm[:SIZE] = _power_up_image()

    # ------------------------------------------------------------------ writes
    def set_ao(self, ao0_v: float, ao1_v: float) -> None:
        """The DACs now drive these voltages."""
        mm = self._mm
        _AO.pack_into(mm, _AO_AT, ao0_v, ao1_v)
        edges, updates, tick = _COUNTS.unpack_from(mm, _EDGES_AT)
        _COUNTS.pack_into(mm, _EDGES_AT, edges, updates + 1, tick)

    def set_do(self, level: bool) -> None:
        """The heartbeat line now sits at ``level`` (an edge is counted when it changes)."""
        mm = self._mm
        level = 1 if level else 0
        if _U32.unpack_from(mm, _DO_AT)[0] != level:
            _U32.pack_into(mm, _DO_AT, level)
            edges, updates, tick = _COUNTS.unpack_from(mm, _EDGES_AT)
            _COUNTS.pack_into(mm, _EDGES_AT, edges + 1, updates, tick)

    def set_tick(self, tick: int) -> None:
        edges, updates, _ = _COUNTS.unpack_from(self._mm, _EDGES_AT)
        _COUNTS.pack_into(self._mm, _EDGES_AT, edges, updates, tick)

    def claim(self) -> None:
        """Record this process as the card's driver."""
        _PID.pack_into(self._mm, _PID_AT, os.getpid())

    def reset_device(self) -> None:
        """As ``nidaqmx.system.Device("Dev1").reset_device()``: AO to 0 V (an MPYE fully open!)."""
        _AO.pack_into(self._mm, _AO_AT, POWER_UP_AO_V, POWER_UP_AO_V)
        _U32.pack_into(self._mm, _DO_AT, 0)

    # ------------------------------------------------------------------- reads
    def state(self) -> CardState:
        _m, _v, do, ao0, ao1, edges, updates, tick, pid = _LAYOUT.unpack_from(self._mm, 0)
        return CardState(ao0, ao1, bool(do), edges, updates, tick, pid)

    def close(self) -> None:
        self._mm.close()


def _power_up_image() -> bytes:
    return _LAYOUT.pack(_MAGIC, _VERSION, 0, POWER_UP_AO_V, POWER_UP_AO_V, 0, 0, 0, os.getpid())


def _create(path: Path) -> None:
    """A new card file at ``path``, whole at once: the power-up image is written to a
    temporary file beside it and linked in, so a reader (another process polling the card)
    never sees it half made, and a file another process made meanwhile is never replaced."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.new")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    try:
        os.write(fd, _power_up_image())
    finally:
        os.close(fd)
    try:
        os.link(tmp, path)
    except FileExistsError:
        pass  # another process powered the card up first: that is the card
    finally:
        os.unlink(tmp)


def read_card_state(path: str | Path) -> CardState:
    """The state a card file holds (e.g. after the process driving it was killed); reading
    never creates a card file or powers one up (a missing file: FileNotFoundError)."""
    path = Path(path)
    CardRegister._refuse_foreign(path)
    with open(path, "rb") as fh:
        head = fh.read(SIZE)
    if len(head) < SIZE:  # an empty file: a card that never powered up, no writer yet
        return CardState(POWER_UP_AO_V, POWER_UP_AO_V, False, 0, 0, 0, 0)
    _m, version, *rest = _LAYOUT.unpack(head)
    if version != _VERSION:
        raise ValueError(f"card file {path}: version {version} refused; allowed: {_VERSION}")
    do, ao0, ao1, edges, updates, tick, pid = rest
    return CardState(ao0, ao1, bool(do), edges, updates, tick, pid)
