"""Our topics as raw CDR bytes, without rclpy: what the nodes publish and take at 1 kHz.

rclpy turns a message object into CDR (and back) in Python-to-C conversions
that are most of a message's cost; publishing pre-serialised
``bytes`` and taking ``raw=True`` subscriptions skips them (DESIGN §10). The
bytes are exactly those rclpy would produce (same layouts as the bag writer,
:mod:`pneu_msgs_py.contract.cdr`, tested against rosbags' and mcap_ros2's
serialisers), so raw and deserialising nodes talk to each other freely.

- :class:`WireCodec` -- one fixed layout: :meth:`~WireCodec.encode` a stamp and
  values into bytes; :meth:`~WireCodec.decode` a payload of that layout (a
  few ``struct`` calls), ``None`` for anything else.
- :class:`SensorWire` -- a :class:`SensorSample` as the five sensor payloads,
  and one payload back to the sample fields it carries (any valid
  FluidPressure / JointState, via the general CDR parser when it is not ours).
- :class:`CommandWire` and :class:`StateWire` -- valve commands and controller
  states; :func:`clock_bytes` -- ``/clock``.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence

from pneu_msgs_py.contract.cdr import (
    CdrDecodeError,
    FixedLayout,
    clock_layout,
    fluid_pressure_layout,
    joint_state_layout,
    parse_fixed,
)
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import (
    JOINT_STATE_TOPIC,
    PRESSURE_TOPICS,
    ROTARY_COUNTS_JOINT,
    valve_joint,
)

__all__ = [
    "CommandWire",
    "SENSOR_TOPICS",
    "SensorWire",
    "StateWire",
    "WireCodec",
    "clock_bytes",
]

#: The five topics one sample is published on, in the order the sim and driver publish them.
SENSOR_TOPICS: tuple[str, ...] = (
    *PRESSURE_TOPICS,
    JOINT_STATE_TOPIC["linear"],
    JOINT_STATE_TOPIC["rotary"],
)
_NS = 1_000_000_000
_STAMP = struct.Struct("<iI")
_NAN = math.nan


class WireCodec:
    """Encode / decode one fixed CDR layout (little endian, as rmw writes it)."""

    __slots__ = ("_const", "_runs", "_stamp_off", "layout", "size", "template")

    def __init__(self, layout: FixedLayout) -> None:
        self.layout = layout
        self.template = layout.template
        self.size = layout.size
        offs = layout.slot_offsets
        self._stamp_off = offs[0]
        runs: list[tuple[int, int]] = []  # (offset, count) of contiguous float64 slots
        for off in offs[2:]:
            if runs and runs[-1][0] + 8 * runs[-1][1] == off:
                runs[-1] = (runs[-1][0], runs[-1][1] + 1)
            else:
                runs.append((off, 1))
        self._runs = tuple((struct.Struct(f"<{n}d"), off, n) for off, n in runs)
        # constant byte ranges (everything but the slots): checked on decode
        slots = [(offs[0], offs[0] + 8)] + [(o, o + 8 * n) for o, n in runs]
        const, pos = [], 0
        for a, b in sorted(slots):
            if a > pos:
                const.append((pos, a))
            pos = b
        if pos < self.size:
            const.append((pos, self.size))
        self._const = tuple(const)

    def encode(self, stamp_ns: int, values: Sequence[float] = ()) -> bytes:
        """The payload of one message (``values`` in ``layout.value_names`` order)."""
        buf = bytearray(self.template)
        sec, nsec = divmod(stamp_ns, _NS)
        _STAMP.pack_into(buf, self._stamp_off, sec, nsec)
        i = 0
        for st, off, n in self._runs:
            st.pack_into(buf, off, *values[i : i + n])
            i += n
        return bytes(buf)

    def decode(self, data: bytes) -> tuple[int, tuple[float, ...]] | None:
        """(stamp_ns, values) of a payload with this layout's constant bytes, else None.

        rmw may pad a payload to a multiple of 4 bytes: up to 3 trailing bytes
        are ignored.
        """
        n = len(data)
        if n < self.size or n > self.size + 3:
            return None
        tpl = self.template
        for a, b in self._const:
            if data[a:b] != tpl[a:b]:
                return None
        sec, nsec = _STAMP.unpack_from(data, self._stamp_off)
        if len(self._runs) == 1:
            st, off, _ = self._runs[0]
            return sec * _NS + nsec, st.unpack_from(data, off)
        vals: tuple[float, ...] = ()
        for st, off, _ in self._runs:
            vals += st.unpack_from(data, off)
        return sec * _NS + nsec, vals


_ROTARY_NAMES = ("rotary", ROTARY_COUNTS_JOINT)


class SensorWire:
    """A sample as the five sensor payloads, and payloads back to sample fields.

    Field names are :class:`SensorSample`'s (``p_c1``, ``p_c2``, ``p_m1``, ``x``,
    ``theta``, ``omega``, ``counts``).
    """

    def __init__(self, variances: dict[str, float] | None = None) -> None:
        self.variances = dict(variances or {})
        self.pressure = {
            t: (attr, WireCodec(fluid_pressure_layout(frame)))
            for t, (attr, frame) in PRESSURE_TOPICS.items()
        }
        self.linear = WireCodec(joint_state_layout(["linear"], position=True))
        self.rotary = WireCodec(joint_state_layout(_ROTARY_NAMES, position=True, velocity=True))
        self._lin_topic = JOINT_STATE_TOPIC["linear"]
        self._rot_topic = JOINT_STATE_TOPIC["rotary"]
        self.fallbacks = 0  # payloads decoded by the general parser (not our exact layout)

    def encode(self, s: SensorSample) -> list[tuple[str, bytes]]:
        """[(topic, payload)] of sample ``s`` in :data:`SENSOR_TOPICS` order."""
        stamp = s.stamp_ns
        var = self.variances
        out = [
            (t, codec.encode(stamp, (getattr(s, attr), var.get(t, 0.0))))
            for t, (attr, codec) in self.pressure.items()
        ]
        out.append((self._lin_topic, self.linear.encode(stamp, (s.x,))))
        out.append(
            (
                self._rot_topic,
                self.rotary.encode(stamp, (s.theta, float(s.counts), s.omega, _NAN)),
            )
        )
        return out

    def decode(self, topic: str, data: bytes) -> tuple[int, dict[str, float]]:
        """(stamp_ns, {sample field: value}) of one sensor payload; ValueError if malformed."""
        p = self.pressure.get(topic)
        if p is not None:
            got = p[1].decode(data)
            if got is not None:
                return got[0], {p[0]: got[1][0]}
            d = self._parse("sensor_msgs/msg/FluidPressure", data)
            return d["stamp_ns"], {p[0]: d["fluid_pressure"]}
        if topic == self._lin_topic:
            got = self.linear.decode(data)
            if got is not None:
                return got[0], {"x": got[1][0]}
            d = self._parse("sensor_msgs/msg/JointState", data)
            return d["stamp_ns"], {"x": _joint(d, "linear", "position")}
        if topic == self._rot_topic:
            got = self.rotary.decode(data)
            if got is not None:
                th, counts, omega, _ = got[1]
                return got[0], {"theta": th, "counts": counts, "omega": omega}
            d = self._parse("sensor_msgs/msg/JointState", data)
            return d["stamp_ns"], {
                "theta": _joint(d, "rotary", "position"),
                "counts": _joint(d, ROTARY_COUNTS_JOINT, "position"),
                "omega": _joint(d, "rotary", "velocity"),
            }
        raise ValueError(f"{topic} is not a sensor topic ({', '.join(SENSOR_TOPICS)})")

    def _parse(self, ros_type: str, data: bytes) -> dict:
        try:
            d = parse_fixed(ros_type, data)
        except CdrDecodeError as err:
            raise ValueError(f"malformed {ros_type} payload: {err}") from None
        self.fallbacks += 1
        return d


def _joint(d: dict, name: str, key: str) -> float:
    names = d["name"]
    if name not in names or len(d[key]) != len(names):
        raise ValueError(f"JointState has no {key} for joint {name!r} (names {names})")
    return float(d[key][names.index(name)])


class CommandWire:
    """Valve commands of one axis: JointState name [<axis>_valve], effort [u V]."""

    def __init__(self, axis: str) -> None:
        self.axis = axis
        self.joint = valve_joint(axis)
        self.codec = WireCodec(joint_state_layout([self.joint], position=False, effort=True))

    def encode(self, stamp_ns: int, u: float) -> bytes:
        return self.codec.encode(stamp_ns, (u,))

    def decode(self, data: bytes) -> tuple[int, float]:
        """(stamp_ns of the answered sample, u V); ValueError if not a command of this axis."""
        got = self.codec.decode(data)
        if got is not None:
            return got[0], got[1][0]
        try:
            d = parse_fixed("sensor_msgs/msg/JointState", data)
        except CdrDecodeError as err:
            raise ValueError(f"malformed valve command: {err}") from None
        return d["stamp_ns"], _joint(d, self.joint, "effort")


class StateWire:
    """Controller states: name = the state fields, position = values, frame_id = algorithm."""

    def __init__(self, fields: Sequence[str]) -> None:
        self.fields = tuple(fields)
        self._codecs: dict[str, WireCodec] = {}

    def encode(self, stamp_ns: int, values: Sequence[float], algorithm: str) -> bytes:
        codec = self._codecs.get(algorithm)
        if codec is None:
            codec = WireCodec(joint_state_layout(self.fields, position=True, frame_id=algorithm))
            self._codecs[algorithm] = codec
        return codec.encode(stamp_ns, values)


_CLOCK = WireCodec(clock_layout())


def clock_bytes(stamp_ns: int) -> bytes:
    """``rosgraph_msgs/msg/Clock`` payload."""
    return _CLOCK.encode(stamp_ns)
