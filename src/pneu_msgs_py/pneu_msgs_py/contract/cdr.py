"""Fixed byte layouts of CDR messages, for bulk encoding and decoding with numpy.

A ROS 2 message whose strings and sequence lengths are fixed (a FluidPressure
with a given ``frame_id``; a JointState with given names and array lengths)
serialises to the same bytes every time except for a few numeric slots: the
header stamp and the float64 values. :class:`FixedLayout` holds that byte
template and the slot offsets, so that

- :meth:`FixedLayout.encode_many` writes N messages as one ``(N, size)`` uint8
  array (one numpy assignment per slot, no per-message Python), and
- :meth:`FixedLayout.decode_many` reads N such messages back with a structured
  dtype view.

CDR rules used (XCDR1, little endian, as rmw and rosbags write them): a 4-byte
encapsulation header ``00 01 00 00``; each primitive aligned to its size
counted from the end of that header; a string is ``uint32 length`` (including
the NUL) + UTF-8 bytes + NUL; a sequence is ``uint32 count`` + elements, and an
empty sequence adds no padding. Tests compare the bytes with rosbags'
``serialize_cdr`` and mcap_ros2's encoder.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "CDR_LE_HEADER",
    "FixedLayout",
    "fluid_pressure_layout",
    "joint_state_layout",
    "clock_layout",
    "parse_fixed",
    "CdrDecodeError",
    "split_stamp",
]

CDR_LE_HEADER = b"\x00\x01\x00\x00"
_NS = 1_000_000_000


class CdrDecodeError(ValueError):
    """A payload does not match the message type it claims to be."""


def split_stamp(stamp_ns: int) -> tuple[int, int]:
    """int nanoseconds -> (sec, nanosec) as builtin_interfaces/Time holds them."""
    sec, nsec = divmod(int(stamp_ns), _NS)
    return sec, nsec


class _Builder:
    """Serialise a message while recording where the numeric slots are."""

    def __init__(self) -> None:
        self.buf = bytearray(CDR_LE_HEADER)
        self.slots: list[tuple[str, int, str]] = []  # (name, offset, numpy format)

    def _align(self, n: int) -> None:
        pad = (-(len(self.buf) - 4)) % n
        self.buf += b"\x00" * pad

    def u32(self, v: int) -> None:
        self._align(4)
        self.buf += struct.pack("<I", v)

    def string(self, s: str) -> None:
        raw = s.encode("utf-8") + b"\x00"
        self.u32(len(raw))
        self.buf += raw

    def stamp(self) -> None:
        self._align(4)
        self.slots.append(("sec", len(self.buf), "<i4"))
        self.slots.append(("nanosec", len(self.buf) + 4, "<u4"))
        self.buf += b"\x00" * 8

    def f64(self, name: str) -> None:
        self._align(8)
        self.slots.append((name, len(self.buf), "<f8"))
        self.buf += b"\x00" * 8

    def f64_seq(self, names: Sequence[str]) -> None:
        self.u32(len(names))
        for n in names:
            self.f64(n)


@dataclass(frozen=True)
class FixedLayout:
    """Template bytes and slot offsets of one fixed-shape CDR message.

    Attributes
    ----------
    ros_type : ``pkg/msg/Type``
    frame_id : the header's frame_id ('' for Clock)
    names : JointState names (empty for other types)
    value_names : names of the float64 slots, in payload order
    template : the payload with every slot zero
    """

    ros_type: str
    frame_id: str
    names: tuple[str, ...]
    value_names: tuple[str, ...]
    template: bytes
    slot_offsets: tuple[int, ...]  # sec, nanosec, then one per value
    dtype: np.dtype = field(repr=False, compare=False)
    const_mask: np.ndarray = field(repr=False, compare=False)

    @property
    def size(self) -> int:
        return len(self.template)

    @classmethod
    def _from_builder(
        cls, ros_type: str, frame_id: str, names: Sequence[str], b: _Builder
    ) -> FixedLayout:
        slots = b.slots
        dtype = np.dtype(
            {
                "names": [s[0] for s in slots],
                "formats": [s[2] for s in slots],
                "offsets": [s[1] for s in slots],
                "itemsize": len(b.buf),
            }
        )
        mask = np.ones(len(b.buf), dtype=bool)
        for _, off, fmt in slots:
            mask[off : off + int(fmt[-1])] = False
        return cls(
            ros_type=ros_type,
            frame_id=frame_id,
            names=tuple(names),
            value_names=tuple(s[0] for s in slots[2:]),
            template=bytes(b.buf),
            slot_offsets=tuple(s[1] for s in slots),
            dtype=dtype,
            const_mask=mask,
        )

    # -- encoding ----------------------------------------------------------
    def encode(self, stamp_ns: int, values: Sequence[float] = ()) -> bytes:
        """One message (slow reference path, ``struct`` into the template)."""
        if len(values) != len(self.value_names):
            raise ValueError(
                f"{self.ros_type}: {len(values)} values given, layout has {len(self.value_names)}"
            )
        buf = bytearray(self.template)
        sec, nsec = split_stamp(stamp_ns)
        struct.pack_into("<iI", buf, self.slot_offsets[0], sec, nsec)
        for off, v in zip(self.slot_offsets[2:], values):
            struct.pack_into("<d", buf, off, v)
        return bytes(buf)

    def encode_many(self, stamps_ns: np.ndarray, values: np.ndarray | None = None) -> np.ndarray:
        """N messages as an ``(N, size)`` uint8 array.

        Parameters
        ----------
        stamps_ns : (N,) int64, header stamps in ns
        values : (N, len(value_names)) float64
        """
        stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
        n = stamps_ns.shape[0]
        out = np.empty((n, self.size), dtype=np.uint8)
        out[:] = np.frombuffer(self.template, dtype=np.uint8)
        rec = out.view(self.dtype)[:, 0]
        sec, nsec = np.divmod(stamps_ns, _NS)
        rec["sec"] = sec
        rec["nanosec"] = nsec
        if self.value_names:
            vals = np.asarray(values, dtype=np.float64).reshape(n, len(self.value_names))
            for i, name in enumerate(self.value_names):
                rec[name] = vals[:, i]
        return out

    # -- decoding ----------------------------------------------------------
    def matches(self, rows: np.ndarray) -> np.ndarray:
        """Which rows of an ``(N, size)`` uint8 array have this layout's constant bytes."""
        tpl = np.frombuffer(self.template, dtype=np.uint8)
        diff = (rows != tpl) & self.const_mask
        return ~diff.any(axis=1)

    def decode_many(self, rows: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """(stamps_ns int64, {value name: float64 array}) from ``(N, size)`` rows.

        The caller has checked :meth:`matches`.
        """
        rec = np.ascontiguousarray(rows).view(self.dtype)[:, 0]
        stamps = rec["sec"].astype(np.int64) * _NS + rec["nanosec"].astype(np.int64)
        return stamps, {n: rec[n].astype(np.float64) for n in self.value_names}


def fluid_pressure_layout(frame_id: str) -> FixedLayout:
    """sensor_msgs/msg/FluidPressure: values (fluid_pressure [Pa], variance [Pa^2])."""
    b = _Builder()
    b.stamp()
    b.string(frame_id)
    b.f64("fluid_pressure")
    b.f64("variance")
    return FixedLayout._from_builder("sensor_msgs/msg/FluidPressure", frame_id, (), b)


def joint_state_layout(
    names: Sequence[str],
    *,
    position: bool = True,
    velocity: bool = False,
    effort: bool = False,
    frame_id: str = "",
) -> FixedLayout:
    """sensor_msgs/msg/JointState with fixed names; each array empty or one value per name.

    Value names are ``<joint>.position``, ``<joint>.velocity``, ``<joint>.effort``.
    """
    b = _Builder()
    b.stamp()
    b.string(frame_id)
    b.u32(len(names))
    for n in names:
        b.string(n)
    for key, on in (("position", position), ("velocity", velocity), ("effort", effort)):
        b.f64_seq([f"{n}.{key}" for n in names] if on else [])
    return FixedLayout._from_builder("sensor_msgs/msg/JointState", frame_id, names, b)


def clock_layout() -> FixedLayout:
    """rosgraph_msgs/msg/Clock: only the stamp (``clock``)."""
    b = _Builder()
    b.stamp()
    return FixedLayout._from_builder("rosgraph_msgs/msg/Clock", "", (), b)


# -- parsing one payload (slow path; also finds the layout of foreign files) --


class _Parser:
    def __init__(self, data: bytes | memoryview) -> None:
        self.data = bytes(data)
        if len(self.data) < 4 or self.data[0] != 0 or self.data[1] not in (0, 1):
            raise CdrDecodeError("bad CDR encapsulation header")
        self.le = self.data[1] == 1
        self.e = "<" if self.le else ">"
        self.pos = 4

    def _align(self, n: int) -> None:
        self.pos += (-(self.pos - 4)) % n

    def _take(self, fmt: str, size: int, align: int):
        self._align(align)
        end = self.pos + size
        if end > len(self.data):
            raise CdrDecodeError("payload too short")
        v = struct.unpack_from(self.e + fmt, self.data, self.pos)
        self.pos = end
        return v

    def u32(self) -> int:
        return self._take("I", 4, 4)[0]

    def stamp_ns(self) -> int:
        sec, nsec = self._take("iI", 8, 4)
        return sec * _NS + nsec

    def string(self) -> str:
        n = self.u32()
        end = self.pos + n
        if n == 0 or end > len(self.data):
            raise CdrDecodeError("bad string length")
        s = self.data[self.pos : end - 1].decode("utf-8")
        self.pos = end
        return s

    def f64(self) -> float:
        return self._take("d", 8, 8)[0]

    def f64_seq(self) -> list[float]:
        n = self.u32()
        if n == 0:
            return []
        if self.pos + 8 * n > len(self.data) + 8:
            raise CdrDecodeError("bad sequence length")
        return list(self._take(f"{n}d", 8 * n, 8))

    def done(self) -> None:
        # rmw pads the serialized size up to a multiple of 4 at most
        if len(self.data) - self.pos > 3:
            raise CdrDecodeError("trailing bytes after message")


def parse_fixed(ros_type: str, data: bytes | memoryview) -> dict:
    """Decode one FluidPressure, JointState or Clock payload into a plain dict.

    Returns keys ``stamp_ns``, ``frame_id`` and per type ``fluid_pressure``,
    ``variance`` / ``name``, ``position``, ``velocity``, ``effort`` / (nothing
    more for Clock). Raises :class:`CdrDecodeError` on malformed payloads.
    """
    p = _Parser(data)
    out: dict = {"stamp_ns": p.stamp_ns()}
    if ros_type == "rosgraph_msgs/msg/Clock":
        out["frame_id"] = ""
    elif ros_type == "sensor_msgs/msg/FluidPressure":
        out["frame_id"] = p.string()
        out["fluid_pressure"] = p.f64()
        out["variance"] = p.f64()
    elif ros_type == "sensor_msgs/msg/JointState":
        out["frame_id"] = p.string()
        out["name"] = [p.string() for _ in range(p.u32())]
        out["position"] = p.f64_seq()
        out["velocity"] = p.f64_seq()
        out["effort"] = p.f64_seq()
    else:
        raise CdrDecodeError(f"no fixed decoder for {ros_type}")
    p.done()
    out["little_endian"] = p.le
    return out


def layout_of(ros_type: str, parsed: dict) -> FixedLayout:
    """The layout a parsed message (from :func:`parse_fixed`) would be encoded with."""
    if ros_type == "rosgraph_msgs/msg/Clock":
        return clock_layout()
    if ros_type == "sensor_msgs/msg/FluidPressure":
        return fluid_pressure_layout(parsed["frame_id"])
    names = parsed["name"]
    n = len(names)
    lens = [len(parsed[k]) for k in ("position", "velocity", "effort")]
    if any(k not in (0, n) for k in lens):
        raise CdrDecodeError("JointState arrays neither empty nor one value per name")
    return joint_state_layout(
        names,
        position=lens[0] == n and n > 0,
        velocity=lens[1] == n and n > 0,
        effort=lens[2] == n and n > 0,
        frame_id=parsed["frame_id"],
    )
