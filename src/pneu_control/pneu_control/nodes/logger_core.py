"""The logger node's work without ROS: serialized messages in, the run's MCAP out.

Two ways to record a ROS run (the launch files' ``recorder`` argument):

``pneu``
    The logger node subscribes to every pneu topic with ``raw=True`` and hands
    the CDR bytes here untouched (no decode on the hot path);
    :class:`LoggerCore` writes them with :meth:`BagWriter.write_serialized`
    and, on :meth:`close`, the metadata below -- one ``.mcap`` laid out as the
    in-process runner's.
``rosbag2``
    ``ros2 bag record -s mcap`` (C++, what ROS users trust; it keeps up at any
    rate) records the topics into a rosbag2 directory, and the logger node
    only gathers the graph's parameters: :meth:`close` writes the metadata
    records as the sidecar :data:`SIDECAR` in that directory, which
    :func:`pneu_msgs_py.bag.reader.read_run` merges into the run's metadata.

The metadata:

- ``pneu.run``, ``pneu.safety``, ``pneu.faults`` -- the records the
  in-process runner writes (``config_json``: axes, seed, duration,
  controllers, windows, plant, safety, faults, ...), rebuilt from the
  parameters of the nodes in the graph, so ``pneu analyze`` treats a ROS run
  like an in-process one (the safe intervals come from ``/diagnostics``, as
  for the runner's bags);
- ``pneu.params<node>`` -- every parameter of every node (JSON values);
- ``pneu.param_changes`` -- the live changes seen on ``/parameter_events``.

Times: in lockstep the log and publish times are the message's own stamp
(``header.stamp``, or ``clock`` for ``/clock``), read from bytes 4–12 of the
CDR payload -- the runner's layout, independent of when the logger got the
message. In realtime they are the receive time (node clock) and the
publisher's source timestamp, as rosbag2 records them.
"""

from __future__ import annotations

import json
import struct
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pneu_msgs_py.bag import BagWriter
from pneu_msgs_py.bag.reader import SIDECAR
from pneu_msgs_py.contract.topics import TOPICS
from pneu_msgs_py.params.core import flatten, to_dict

from pneu_control.controller.axis import STATE_FIELDS
from pneu_control.experiment.bag_log import RUN_METADATA, run_metadata

__all__ = [
    "LOGGED_TOPICS",
    "LoggerCore",
    "SIDECAR",
    "stamp_from_cdr",
    "run_config_from_params",
]

#: (topic, ros type) of everything the logger records: the topic table.
LOGGED_TOPICS: tuple[tuple[str, str], ...] = tuple((t.name, t.ros_type) for t in TOPICS)

_LE = struct.Struct("<iI")
_BE = struct.Struct(">iI")
_NS = 1_000_000_000
SIM_NODE = "/pneu_sim"
DRIVER_NODE = "/pneu_driver"
CONTROLLER_NODE = {"linear": "/linear_controller", "rotary": "/rotary_controller"}


def stamp_from_cdr(data: bytes | memoryview) -> int:
    """The leading ``builtin_interfaces/Time`` of a CDR message, int ns.

    Every stamped pneu type starts with it (``std_msgs/Header.stamp``,
    ``rosgraph_msgs/Clock.clock``): int32 sec and uint32 nanosec right after
    the 4-byte encapsulation header (byte 1: 0 big-endian, 1 little-endian).
    """
    if len(data) < 12:
        raise ValueError(f"CDR payload of {len(data)} bytes has no stamp")
    sec, nsec = (_LE if data[1] & 1 else _BE).unpack_from(data, 4)
    return sec * _NS + nsec


def _node_values(params: Mapping[str, Any], names: Any) -> dict[str, Any]:
    return {k: v for k, v in params.items() if k in names}


def run_config_from_params(node_params: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """The runner's config echo (``pneu.run``.config_json) from the graph's parameters.

    Controllers: ``/linear_controller`` and ``/rotary_controller`` (their
    parameters are :class:`AxisControllerParams`); the run: ``/pneu_sim``
    (seed, duration, x0, plant file) or ``/pneu_driver`` (the rig).
    """
    from pneu_control.controller.params import AxisControllerParams, params_from_mapping
    from pneu_control.experiment.session import window_for
    from pneu_msgs_py import __version__

    known = set(flatten(AxisControllerParams()))
    controllers: dict[str, Any] = {}
    windows: dict[str, Any] = {}
    problems: list[str] = []
    for axis, node in CONTROLLER_NODE.items():
        values = node_params.get(node)
        if not values:
            continue
        nested: dict[str, Any] = {}
        for key, v in _node_values(values, known).items():
            d = nested
            *head, last = key.split(".")
            for part in head:
                d = d.setdefault(part, {})
            d[last] = tuple(v) if isinstance(v, list) else v
        try:
            p = params_from_mapping(nested)
        except ValueError as err:
            problems.append(f"{node}: {err}")
            continue
        controllers[axis] = to_dict(p)
        windows[axis] = window_for(axis, p.reference).to_dict()
    sim = node_params.get(SIM_NODE, {})
    axes = [a for a in ("linear", "rotary") if a in controllers]
    out: dict[str, Any] = {
        "name": "ros",
        "axes": axes,
        "controllers": controllers,
        "windows": windows,
        "version": __version__,
        "source": "sim" if sim else ("rig" if DRIVER_NODE in node_params else "unknown"),
    }
    if sim:
        out.update(
            seed=sim.get("seed"),
            duration_s=sim.get("duration_s"),
            x0=sim.get("x0"),
            mode=sim.get("mode"),
        )
        try:
            from pneu_sim.physics.plant_file import load_plant

            out["plant"] = to_dict(load_plant(sim.get("plant_file") or None))
        except (OSError, ValueError) as err:
            problems.append(f"{SIM_NODE}: plant: {err}")
        try:
            from pneu_sim.nodes.sim_core import load_faults

            faults = load_faults(sim.get("faults", ""), sim.get("faults_file", ""))
            out["faults"] = [f.to_dict() for f in faults]
        except (OSError, ValueError) as err:
            problems.append(f"{SIM_NODE}: faults: {err}")
    run_node = sim or node_params.get(DRIVER_NODE, {})
    if run_node:
        out["safety"] = None
        if run_node.get("safety", True):  # the driver always has its supervisor
            try:
                from pneu_driver.safety import load_safety_params

                out["safety"] = to_dict(load_safety_params(run_node.get("safety_file") or None))
            except (OSError, ValueError) as err:
                problems.append(f"safety: {err}")
    if problems:
        out["problems"] = problems
    return out


def _warm_imports() -> None:
    """Import what :func:`run_config_from_params` uses (the twin's modules, numba): seconds on a
    busy machine, which a Ctrl-C'd node must not spend before its bag is closed."""
    import pneu_driver.safety  # noqa: F401
    import pneu_sim.faults.injection
    import pneu_sim.nodes.sim_core
    import pneu_sim.physics.plant_file  # noqa: F401

    import pneu_control.controller.params
    import pneu_control.experiment.session  # noqa: F401


class LoggerCore:
    """Write raw CDR messages and the graph's parameters to one MCAP file (``record``), or
    only the parameters, as the sidecar of a rosbag2 directory ``path`` (see module docstring)."""

    def __init__(
        self,
        path: str | Path,
        *,
        mode: str = "lockstep",
        compression: str = "zstd",
        record: bool = True,
    ):
        self.path = Path(path)
        self.mode = mode
        self.record = record
        self.closed = False
        self.writer = (
            BagWriter(
                self.path, controller_state_fields=STATE_FIELDS, qos=mode, compression=compression
            )
            if record
            else None
        )
        self.node_params: dict[str, dict[str, Any]] = {}
        self.changes: list[dict[str, Any]] = []
        # what close() needs, loaded now in the background: a shutdown must be quick, and the
        # node must be up at once to catch the graph's parameters
        threading.Thread(target=_warm_imports, name="logger_warm_imports", daemon=True).start()
        self.counts: dict[str, int] = {}
        self.bad = 0
        self._lockstep = mode == "lockstep"

    def on_message(
        self, topic: str, ros_type: str, data: bytes, receive_ns: int, source_ns: int
    ) -> None:
        """One serialized message (times int ns; see the module docstring for which are used)."""
        if self.writer is None:
            return
        if self._lockstep:
            try:
                receive_ns = source_ns = stamp_from_cdr(data)
            except ValueError:
                self.bad += 1
                return
        self.writer.write_serialized(topic, ros_type, data, receive_ns, source_ns)
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def set_node_params(self, node: str, values: Mapping[str, Any]) -> None:
        """All parameters of ``node`` (read from its parameter service), replacing what was
        known."""
        self.node_params[node] = dict(values)

    def on_parameter_event(self, stamp_ns: int, node: str, changed: Mapping[str, Any]) -> None:
        """New or changed parameters of ``node`` (from ``/parameter_events``)."""
        self.node_params.setdefault(node, {}).update(changed)
        for name, value in changed.items():
            self.changes.append(
                {"stamp_ns": int(stamp_ns), "node": node, "name": name, "value": value}
            )

    def metadata(self) -> dict[str, dict[str, str]]:
        """The metadata records written on :meth:`close`."""
        config = run_config_from_params(self.node_params)
        out = run_metadata(json.loads(json.dumps(config, default=str)))  # the runner's records
        out[RUN_METADATA]["source"] = f"pneu logger node (ROS 2 graph, {self.mode})"
        out["pneu.param_changes"] = {"changes_json": json.dumps(self.changes, default=str)}
        for node, values in sorted(self.node_params.items()):
            out[f"pneu.params{node}"] = {
                k: json.dumps(v, default=str) for k, v in sorted(values.items())
            }
        return out

    def close(self) -> Path:
        """Write the metadata and finish the file (summary, footer); idempotent. Returns the
        file written (the bag, or the sidecar)."""
        if self.closed:
            return self.path if self.record else self.sidecar_path
        self.closed = True
        if self.writer is None:
            return self._write_sidecar()
        try:
            for name, rec in self.metadata().items():
                self.writer.add_metadata(name, rec)
        finally:
            self.writer.close()
        return self.path

    @property
    def sidecar_path(self) -> Path:
        """Inside the rosbag2 directory if the recorder made it, else beside where it would be."""
        if self.path.is_dir():
            return self.path / SIDECAR
        return self.path.parent / f"{self.path.name}.{SIDECAR}"

    def _write_sidecar(self) -> Path:
        """The metadata records as JSON, written under a temporary name and renamed."""
        path = self.sidecar_path
        tmp = path.with_name(path.name + ".partial")
        tmp.write_text(json.dumps(self.metadata(), indent=1, sort_keys=True) + "\n")
        tmp.replace(path)
        return path
