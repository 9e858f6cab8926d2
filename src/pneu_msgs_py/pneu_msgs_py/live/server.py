"""Serve a run to the Foxglove app over its WebSocket protocol (``foxglove-sdk``), without ROS.

The same topics, types and bytes as the run's bag: every channel carries CDR
payloads (:mod:`pneu_msgs_py.contract.wire`, byte for byte what the bag
writer and the rclpy shells produce) with the ``ros2msg`` schema text the bag
stores (:mod:`pneu_msgs_py.bag.schemas`), so Foxglove decodes them exactly as
it decodes a bag or ``foxglove_bridge``, and a layout made for the bag works
live. Each message is logged at its sample stamp (the bag's log time).

Pacing: ``realtime`` holds the writer back so that stamps advance with the
wall clock (sleeps only when 2 ms or more ahead; a writer slower than real
time runs at its own speed); ``fast`` never waits. Messages logged while no
viewer subscribes are dropped by the SDK (no backlog), so a caller that wants
the whole run waits for a viewer first (:meth:`LiveServer.wait_for_viewer`).

``foxglove-sdk`` is an optional dependency: it is imported when a server
starts, and its absence is one :class:`~pneu_msgs_py.live.errors.LiveError` line.
"""

from __future__ import annotations

import socket
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any

from pneu_msgs_py.bag.schemas import MESSAGE_ENCODING, SCHEMA_ENCODING, msgdef
from pneu_msgs_py.contract.convert import DiagStatus, diagnostics_to_typestore, typestore_messages
from pneu_msgs_py.contract.samples import AXES, SensorSample
from pneu_msgs_py.contract.topics import (
    CONTROLLER_STATE_TOPIC,
    DEFAULT_STATE_FIELDS,
    DIAGNOSTICS_TOPIC,
    PRESSURE_TOPICS,
    TOPIC_BY_NAME,
    VALVE_COMMAND_TOPIC,
)
from pneu_msgs_py.contract.wire import SENSOR_TOPICS, CommandWire, SensorWire, StateWire
from pneu_msgs_py.live.errors import LiveError
from pneu_msgs_py.params.core import ParamError

__all__ = ["DEFAULT_PORT", "LiveServer", "SUBPROTOCOL"]

DEFAULT_PORT = 8765  # Foxglove's default for a WebSocket connection
SUBPROTOCOL = "foxglove.sdk.v1"  # what foxglove-sdk >= 0.30 speaks (ws-protocol v1 framing)
_PACES = ("realtime", "fast")
_SLEEP_MIN_NS = 2_000_000  # realtime pacing sleeps only when this far ahead of the wall clock
_INSTALL = "python3 -m pip install 'foxglove-sdk>=0.30'"


def _foxglove() -> Any:
    try:
        import foxglove
    except ImportError:
        raise LiveError(f"the live view needs the foxglove-sdk package: {_INSTALL}") from None
    return foxglove


def _bind_refusal(host: str, port: int, err: Exception) -> str:
    """One line naming the option the server could not start on: the port (in use, not
    allowed) or the host (no such name, not an address of this machine)."""
    text = str(err).split("Failed to bind port: ", 1)[-1]  # foxglove's own words, once
    if "in use" in text or "ermission denied" in text:
        hint = "; --live 0 picks a free port" if port else ""
        return f"--live: {port} refused; allowed: a port free to serve on ({text}){hint}"
    return (
        f"--live-host: {host!r} refused; allowed: a name or address of this machine "
        f"(127.0.0.1, 0.0.0.0: every interface, ::1) ({text})"
    )


class LiveServer:
    """A Foxglove WebSocket server carrying one run (implements :class:`~pneu_msgs_py.live.sink.RunSink`).

    Parameters
    ----------
    axes : the axes whose valve command (and controller state) topics are advertised
    port : TCP port (0 = any free port; the bound one is :attr:`port`)
    host : interface to listen on (``127.0.0.1``: this machine only; ``0.0.0.0``: every one)
    pace : ``realtime`` | ``fast`` (see the module docstring)
    controller_state : advertise ``/pneu/<axis>/controller_state`` (False for open-loop runs)
    state_fields : names of the controller-state values, in order
    pressure_variance : FluidPressure.variance [Pa^2], as the bag writes it
    clock_ns, sleep : the wall clock and sleep used by realtime pacing
    """

    def __init__(
        self,
        *,
        axes: Iterable[str] = AXES,
        port: int = DEFAULT_PORT,
        host: str = "127.0.0.1",
        pace: str = "realtime",
        controller_state: bool = True,
        state_fields: Sequence[str] = DEFAULT_STATE_FIELDS,
        pressure_variance: float = 0.0,
        name: str = "pneu",
        clock_ns: Callable[[], int] = time.monotonic_ns,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        axes = tuple(axes)
        if not set(axes) <= set(AXES):
            raise ParamError("live.axes", axes, f"a subset of {AXES}")
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise ParamError("live.port", port, "an integer 0 (any free port) to 65535")
        if pace not in _PACES:
            raise ParamError("live.pace", pace, " | ".join(_PACES))
        fg = _foxglove()
        self.pace = pace
        self.host = host
        self._clock_ns, self._sleep = clock_ns, sleep
        self._t0_ns: int | None = None  # wall time of stamp 0 (realtime pacing)
        self._ctx = fg.Context()
        try:
            self._server = fg.start_server(name=name, host=host, port=port, context=self._ctx)
        except RuntimeError as err:  # foxglove's FoxgloveError (bind failure, bad host)
            raise LiveError(_bind_refusal(host, port, err)) from None
        self.port = int(self._server.port)
        self._closed = False

        self._sensor = SensorWire(dict.fromkeys(PRESSURE_TOPICS, pressure_variance))
        self._cmd = {a: CommandWire(a) for a in axes}
        self._state = StateWire(state_fields) if controller_state else None
        topics = [*SENSOR_TOPICS]
        for a in axes:
            topics.append(VALVE_COMMAND_TOPIC[a])
            if controller_state:
                topics.append(CONTROLLER_STATE_TOPIC[a])
        topics.append(DIAGNOSTICS_TOPIC)
        self._channels = {t: self._channel(fg, t) for t in topics}
        self._sensor_channels = [self._channels[t] for t in SENSOR_TOPICS]

    def _channel(self, fg: Any, topic: str) -> Any:
        ros_type = TOPIC_BY_NAME[topic].ros_type
        schema = fg.Schema(name=ros_type, encoding=SCHEMA_ENCODING, data=msgdef(ros_type).encode())
        return fg.Channel(
            topic, schema=schema, message_encoding=MESSAGE_ENCODING, context=self._ctx
        )

    # -- what a viewer sees ----------------------------------------------------
    @property
    def topics(self) -> tuple[str, ...]:
        """The advertised topics, in advertising order."""
        return tuple(self._channels)

    @property
    def url(self) -> str:
        """``ws://host:port`` to open in Foxglove (Open connection -> Foxglove WebSocket)."""
        host = self.host
        if host in ("0.0.0.0", "::", ""):
            host = socket.gethostname()
        elif ":" in host:
            host = f"[{host}]"
        return f"ws://{host}:{self.port}"

    def subscribed(self) -> tuple[str, ...]:
        """The topics a connected client subscribes to now."""
        return tuple(t for t, ch in self._channels.items() if ch.has_sinks())

    def has_viewer(self) -> bool:
        """Is any channel subscribed by a connected client?"""
        return any(ch.has_sinks() for ch in self._channels.values())

    def wait_for_viewer(self, timeout_s: float) -> bool:
        """Block until a client subscribes to a topic or ``timeout_s`` passes; True if one did."""
        deadline = time.monotonic() + max(0.0, timeout_s)
        while not self.has_viewer():
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.02)
        return True

    # -- RunSink ---------------------------------------------------------------
    def write_cycle(
        self, s: SensorSample, answers: Sequence[tuple[str, float, Sequence[float], str]]
    ) -> None:
        """The sample's five sensor messages, then per answering axis its valve command and
        controller state, all at ``s.stamp_ns`` (the bag's records of one cycle)."""
        stamp = s.stamp_ns
        if self.pace == "realtime":
            self._pace(stamp)
        if any(ch.has_sinks() for ch in self._sensor_channels):
            for ch, (_, payload) in zip(self._sensor_channels, self._sensor.encode(s)):
                ch.log(payload, log_time=stamp)
        for axis, u, values, algorithm in answers:
            self.write_command(axis, stamp, u)
            if self._state is not None:
                ch = self._channels[CONTROLLER_STATE_TOPIC[axis]]
                if ch.has_sinks():
                    ch.log(self._state.encode(stamp, values, algorithm), log_time=stamp)

    def write_command(self, axis: str, stamp_ns: int, u: float) -> None:
        """Valve command ``u`` [V] answering the sample stamped ``stamp_ns``."""
        ch = self._channels.get(VALVE_COMMAND_TOPIC.get(axis, ""))
        if ch is None:
            raise ValueError(f"axis: {axis!r} refused; allowed: {tuple(self._cmd)}")
        if ch.has_sinks():
            ch.log(self._cmd[axis].encode(stamp_ns, u), log_time=stamp_ns)

    def write_diagnostics(self, stamp_ns: int, statuses: Sequence[DiagStatus]) -> None:
        """``/diagnostics`` (CDR by the rosbags Jazzy typestore, as the bag writer encodes it)."""
        ch = self._channels[DIAGNOSTICS_TOPIC]
        if ch.has_sinks():
            msg = diagnostics_to_typestore(stamp_ns, statuses)
            data = bytes(
                typestore_messages().serialize_cdr(msg, "diagnostic_msgs/msg/DiagnosticArray")
            )
            ch.log(data, log_time=stamp_ns)

    def _pace(self, stamp_ns: int) -> None:
        now = self._clock_ns()
        if self._t0_ns is None:
            self._t0_ns = now - stamp_ns
            return
        ahead = self._t0_ns + stamp_ns - now
        if ahead >= _SLEEP_MIN_NS:
            self._sleep(ahead * 1e-9)

    # -- lifetime --------------------------------------------------------------
    def close(self) -> None:
        """Stop serving (connected viewers see the connection close); idempotent."""
        if not self._closed:
            self._closed = True
            self._server.stop()

    def __enter__(self) -> LiveServer:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
