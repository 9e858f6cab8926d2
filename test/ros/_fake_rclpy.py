"""An in-memory stand-in for the parts of rclpy 7.1 (Jazzy) the pneu shells call.

Only for ``test_ros_shells_offline.py`` on machines without ROS: it runs the
real node modules (sim_node, controller_node, logger_node, driver_node) so
their wiring is exercised here. It is NOT rclpy -- the rclpy tests
(``test_ros_rclpy_*.py``) are the real check on a ROS machine. What it
reproduces, read from rclpy's jazzy sources (``rclpy/node.py``):

- parameters: the type is fixed at declaration; overrides win over defaults;
  ``set_parameters`` = one atomic set per parameter; order pre-set callbacks
  (may replace the list) -> descriptor checks (read-only, type, ranges) ->
  on-set callbacks (first refusal wins) -> store -> post-set callbacks;
  on-set/post-set also run on declaration; pre-set does not;
- subscriptions: callbacks with one argument get the message, with two the
  message and an info dict (``source_timestamp``, ``received_timestamp``);
  ``raw=True`` delivers the CDR bytes;
- delivery is asynchronous (queued, run by the executor), messages are
  copied on publish (rclpy serialises), CDR bytes are made with rosbags'
  Jazzy typestore;
- ``/clock`` drives the clock of nodes with ``use_sim_time``.
"""

from __future__ import annotations

import array
import collections
import contextlib
import copy
import enum
import inspect
import struct
import sys
import time
import types
from collections.abc import Iterator

import numpy as np


class World:
    """The middleware: topics, queued deliveries, nodes, services."""

    def __init__(self) -> None:
        self.subs: dict[str, list] = collections.defaultdict(list)
        self.pubs: dict[str, list] = collections.defaultdict(list)
        self.queue: collections.deque = collections.deque()
        self.services: dict[str, tuple] = {}
        self.nodes: list = []
        self.overrides: dict[str, dict] = {}
        self.sim_time_ns = 0
        self._ts = None

    def cdr(self, msg) -> bytes:
        if self._ts is None:
            from rosbags.typesys import Stores, get_typestore

            self._ts = get_typestore(Stores.ROS2_JAZZY)
        if msg is None:
            return b""
        ts = self._ts

        def conv(m, tname):
            cls = ts.types[tname]
            kw = {}
            for f in cls.__dataclass_fields__:
                if f.startswith("__"):
                    continue
                v = getattr(m, f)
                if hasattr(v, "_type"):
                    v = conv(v, v._type)
                elif f in (
                    "position", "velocity", "effort", "positions", "velocities", "accelerations"
                ):  # fmt: skip
                    v = np.array(v, dtype=np.float64)
                elif isinstance(v, list) and v and hasattr(v[0], "_type"):
                    v = [conv(x, x._type) for x in v]
                elif isinstance(v, bytes):
                    v = v[0]
                kw[f] = v
            return cls(**kw)

        return bytes(ts.serialize_cdr(conv(msg, msg._type), msg._type))

    def call(self, service: str):
        """Call a ``std_srvs/Trigger``-like service; returns the response."""
        srv, cb = self.services[service]
        return cb(srv.Request(), srv.Response())


WORLD = World()


def _msg(ros_type: str, fields: dict, consts: dict | None = None) -> type:
    def __init__(self, **kw):
        for k, default in fields.items():
            setattr(
                self, k, kw.pop(k) if k in kw else (default() if callable(default) else default)
            )
        if kw:
            raise TypeError(f"{ros_type}: unknown fields {sorted(kw)}")

    cls = type(ros_type.rsplit("/", 1)[-1], (), {"__init__": __init__, "_type": ros_type})
    for k, v in (consts or {}).items():
        setattr(cls, k, v)
    return cls


def _darr():
    return array.array("d")


Time = _msg("builtin_interfaces/msg/Time", {"sec": 0, "nanosec": 0})
Header = _msg("std_msgs/msg/Header", {"stamp": Time, "frame_id": ""})
FluidPressure = _msg(
    "sensor_msgs/msg/FluidPressure", {"header": Header, "fluid_pressure": 0.0, "variance": 0.0}
)
JointState = _msg(
    "sensor_msgs/msg/JointState",
    {"header": Header, "name": list, "position": _darr, "velocity": _darr, "effort": _darr},
)
KeyValue = _msg("diagnostic_msgs/msg/KeyValue", {"key": "", "value": ""})
DiagnosticStatus = _msg(
    "diagnostic_msgs/msg/DiagnosticStatus",
    {"level": b"\x00", "name": "", "message": "", "hardware_id": "", "values": list},
    {"OK": b"\x00", "WARN": b"\x01", "ERROR": b"\x02", "STALE": b"\x03"},
)
DiagnosticArray = _msg("diagnostic_msgs/msg/DiagnosticArray", {"header": Header, "status": list})
ClockMsg = _msg("rosgraph_msgs/msg/Clock", {"clock": Time})
Duration = _msg("builtin_interfaces/msg/Duration", {"sec": 0, "nanosec": 0})
JointTrajectoryPoint = _msg(
    "trajectory_msgs/msg/JointTrajectoryPoint",
    {
        "positions": _darr,
        "velocities": _darr,
        "accelerations": _darr,
        "effort": _darr,
        "time_from_start": Duration,
    },
)
JointTrajectory = _msg(
    "trajectory_msgs/msg/JointTrajectory",
    {"header": Header, "joint_names": list, "points": list},
)
FloatingPointRange = _msg(
    "rcl_interfaces/msg/FloatingPointRange", {"from_value": 0.0, "to_value": 0.0, "step": 0.0}
)
IntegerRange = _msg("rcl_interfaces/msg/IntegerRange", {"from_value": 0, "to_value": 0, "step": 0})
ParameterDescriptor = _msg(
    "rcl_interfaces/msg/ParameterDescriptor",
    {
        "name": "",
        "type": 0,
        "description": "",
        "additional_constraints": "",
        "read_only": False,
        "dynamic_typing": False,
        "floating_point_range": list,
        "integer_range": list,
    },
)
SetParametersResult = _msg(
    "rcl_interfaces/msg/SetParametersResult", {"successful": False, "reason": ""}
)
ParameterEvent = _msg(
    "rcl_interfaces/msg/ParameterEvent",
    {
        "stamp": Time,
        "node": "",
        "new_parameters": list,
        "changed_parameters": list,
        "deleted_parameters": list,
    },
)


class Trigger:
    Request = _msg("std_srvs/srv/Trigger_Request", {})
    Response = _msg("std_srvs/srv/Trigger_Response", {"success": False, "message": ""})


class Parameter:
    class Type(enum.Enum):
        NOT_SET = 0
        BOOL = 1
        INTEGER = 2
        DOUBLE = 3
        STRING = 4
        DOUBLE_ARRAY = 8

        @classmethod
        def from_parameter_value(cls, v):
            if v is None:
                return cls.NOT_SET
            if isinstance(v, bool):
                return cls.BOOL
            if isinstance(v, int):
                return cls.INTEGER
            if isinstance(v, float):
                return cls.DOUBLE
            if isinstance(v, str):
                return cls.STRING
            if isinstance(v, (list, tuple, array.array)) and all(isinstance(x, float) for x in v):
                return cls.DOUBLE_ARRAY
            raise TypeError(f"The given value is not one of the allowed types '{v}'.")

    def __init__(self, name, type_=None, value=None):
        self.name = name
        self.type_ = type_ or Parameter.Type.from_parameter_value(value)
        self.value = value


class ParameterException(Exception):
    pass


class ExternalShutdownException(Exception):
    pass


class Future:
    def __init__(self):
        self._done, self._result, self._cbs = False, None, []

    def done(self):
        return self._done

    def result(self):
        return self._result

    def set_result(self, r):
        self._done, self._result = True, r
        for cb in self._cbs:
            cb(self)

    def add_done_callback(self, cb):
        self._cbs.append(cb)
        if self._done:
            cb(self)


class ClockType(enum.Enum):
    ROS_TIME = 1
    SYSTEM_TIME = 2
    STEADY_TIME = 3


class _Time:
    def __init__(self, ns):
        self.nanoseconds = ns


class Clock:
    def __init__(self, *, clock_type=ClockType.SYSTEM_TIME):
        self.clock_type = clock_type
        self._sim = False

    def now(self):
        return _Time(WORLD.sim_time_ns if self._sim else time.time_ns())


class _Logger:
    def __init__(self, name):
        self.name, self.lines = name, []

    def _log(self, level, msg):
        self.lines.append((level, msg))

    def info(self, m, **kw):
        self._log("INFO", m)

    def warning(self, m, **kw):
        self._log("WARN", m)

    def error(self, m, **kw):
        self._log("ERROR", m)


class _Publisher:
    def __init__(self, msg_type, topic):
        self.msg_type, self.topic = msg_type, topic
        WORLD.pubs[topic].append(self)

    def publish(self, msg):
        if isinstance(msg, bytes):  # rclpy: pre-serialised CDR goes out as it is (publish_raw)
            data = msg
            msg = None
        elif not isinstance(msg, self.msg_type):
            raise TypeError(f"Expected {self.msg_type} or bytes, got {type(msg)}")
        else:
            data = WORLD.cdr(msg)
        if self.topic == "/clock":
            sec, nsec = struct.unpack_from("<iI", data, 4)
            WORLD.sim_time_ns = sec * 1_000_000_000 + nsec
        for sub in list(WORLD.subs[self.topic]):
            m = copy.deepcopy(msg) if msg is not None else None
            WORLD.queue.append((sub.deliver, (m, data)))

    def get_subscription_count(self):
        return len(WORLD.subs[self.topic])

    def wait_for_all_acked(self, timeout=None):
        return True  # one FIFO queue delivers every message before any published later


class Duration:
    def __init__(self, *, seconds=0.0, nanoseconds=0):
        self.nanoseconds = int(seconds * 1e9) + nanoseconds


class _Subscription:
    def __init__(self, msg_type, topic, cb, raw):
        self.msg_type, self.topic, self.cb, self.raw = msg_type, topic, cb, raw
        try:
            inspect.signature(cb).bind(object())
            self.with_info = False
        except TypeError:
            inspect.signature(cb).bind(object(), object())
            self.with_info = True
        WORLD.subs[topic].append(self)

    def get_publisher_count(self):
        return len(WORLD.pubs[self.topic])

    def deliver(self, msg, data):
        if not self.raw and msg is None:  # bytes published, a deserialising subscriber
            WORLD.cdr(None) if WORLD._ts is None else None
            msg = WORLD._ts.deserialize_cdr(data, self.msg_type._type)
        m = data if self.raw else msg
        if self.with_info:
            now = time.time_ns()
            self.cb(m, {"source_timestamp": now, "received_timestamp": now})
        else:
            self.cb(m)


class _Timer:
    def __init__(self, period, cb):
        self.period, self.cb = period, cb
        self.next = time.monotonic() + period

    def cancel(self):
        self.period = None


class Node:
    def __init__(self, node_name, **kw):
        self._name = node_name
        self._params: dict[str, Parameter] = {}
        self._descs: dict[str, ParameterDescriptor] = {}
        self._pre, self._on, self._post = [], [], []
        self._fake_timers, self._fake_subs = [], []
        self._logger = _Logger(node_name)
        self._overrides = dict(WORLD.overrides.get("/" + node_name, {}))
        self.declare_parameter("use_sim_time", False)
        WORLD.nodes.append(self)

    # -- parameters
    def has_parameter(self, name):
        return name in self._params

    def declare_parameter(self, name, value=None, descriptor=None):
        return self.declare_parameters("", [(name, value, descriptor or ParameterDescriptor())])[0]

    def declare_parameters(self, namespace, parameters):
        out = []
        for name, value, desc in parameters:
            desc.type = Parameter.Type.from_parameter_value(value).value
            if name in self._overrides:
                value = self._overrides[name]
            p = Parameter(name, value=value)
            r = self._apply_descriptor(p, desc, check_read_only=False)
            if r.successful:
                for cb in self._on:
                    r = cb([p])
                    if not r.successful:
                        break
            if not r.successful:
                raise ParameterException(f"{name}: {r.reason}")
            self._params[name], self._descs[name] = p, desc
            for cb in self._post:
                cb([p])
            out.append(p)
        return out

    def _apply_descriptor(self, p, desc, check_read_only=True):
        if check_read_only and desc.read_only:
            return SetParametersResult(
                successful=False, reason=f"Trying to set a read-only parameter: {p.name}."
            )
        if p.type_.value != desc.type:
            return SetParametersResult(
                successful=False,
                reason=f"Wrong parameter type, expected '{Parameter.Type(desc.type)}' got '{p.type_}'",
            )
        for rng, typ in (
            (desc.floating_point_range, Parameter.Type.DOUBLE),
            (desc.integer_range, Parameter.Type.INTEGER),
        ):
            if p.type_ == typ and rng and not rng[0].from_value <= p.value <= rng[0].to_value:
                return SetParametersResult(
                    successful=False,
                    reason=f"Parameter {p.name} out of range Min: {rng[0].from_value}, Max: {rng[0].to_value}, value: {p.value}",
                )
        return SetParametersResult(successful=True)

    def get_parameter(self, name):
        return self._params[name]

    def add_pre_set_parameters_callback(self, cb):
        self._pre.insert(0, cb)

    def add_on_set_parameters_callback(self, cb):
        self._on.insert(0, cb)

    def add_post_set_parameters_callback(self, cb):
        self._post.insert(0, cb)

    def set_parameters(self, parameter_list):
        return [self.set_parameters_atomically([p]) for p in parameter_list]

    def set_parameters_atomically(self, parameter_list):
        if self._pre:
            modified = []
            for cb in self._pre:
                modified.extend(cb(parameter_list))
            parameter_list = modified
        for p in parameter_list:
            r = self._apply_descriptor(p, self._descs[p.name])
            if not r.successful:
                return r
        for cb in self._on:
            r = cb(parameter_list)
            if not r.successful:
                return r
        for p in parameter_list:
            self._params[p.name] = p
        for cb in self._post:
            cb(parameter_list)
        return SetParametersResult(successful=True)

    # -- entities
    def create_publisher(self, msg_type, topic, qos_profile, **kw):
        return _Publisher(msg_type, topic)

    def create_subscription(self, msg_type, topic, callback, qos_profile, *, raw=False, **kw):
        s = _Subscription(msg_type, topic, callback, raw)
        self._fake_subs.append(s)
        return s

    def create_timer(
        self, timer_period_sec, callback, callback_group=None, clock=None, autostart=True
    ):
        t = _Timer(timer_period_sec, callback)
        self._fake_timers.append(t)
        return t

    def create_service(self, srv_type, srv_name, callback, **kw):
        WORLD.services[srv_name.replace("~", "/" + self._name)] = (srv_type, callback)

    def get_clock(self):
        c = Clock(clock_type=ClockType.ROS_TIME)
        c._sim = bool(self._params["use_sim_time"].value)
        return c

    def get_logger(self):
        return self._logger

    def get_name(self):
        return self._name

    def count_publishers(self, topic):
        return 1  # this node's own: one driver or sim on the fake graph

    def count_subscribers(self, topic):
        return len(WORLD.subs[topic])

    def get_fully_qualified_name(self):
        return "/" + self._name

    def get_node_names_and_namespaces(self):
        return [(n._name, "/") for n in WORLD.nodes]

    def destroy_node(self):
        for s in self._fake_subs:
            WORLD.subs[s.topic].remove(s)
        self._fake_subs = []
        self._fake_timers = []
        if self in WORLD.nodes:
            WORLD.nodes.remove(self)


class AsyncParameterClient:
    def __init__(self, node, remote_node_name, **kw):
        self.remote = next(n for n in WORLD.nodes if "/" + n._name == remote_node_name)

    def services_are_ready(self):
        return True

    def _later(self, result, callback):
        f = Future()
        if callback:
            f.add_done_callback(callback)
        WORLD.queue.append((f.set_result, (result,)))
        return f

    def list_parameters(self, prefixes=None, depth=None, callback=None):
        names = list(self.remote._params)
        return self._later(
            types.SimpleNamespace(result=types.SimpleNamespace(names=names)), callback
        )

    def get_parameters(self, names, callback=None):
        values = [self.remote._params[n].value for n in names]
        return self._later(types.SimpleNamespace(values=values), callback)


class SingleThreadedExecutor:
    def __init__(self):
        self.nodes = []

    def add_node(self, node):
        self.nodes.append(node)

    def spin_once(self, timeout_sec=None):
        if WORLD.queue:
            fn, args = WORLD.queue.popleft()
            fn(*args)
            return
        now = time.monotonic()
        for n in list(self.nodes):
            for t in list(n._fake_timers):
                if t.period is not None and now >= t.next:
                    t.next = now + t.period
                    t.cb()
        time.sleep(0.0005)

    def spin_until_future_complete(self, future, timeout_sec=None):
        t_end = time.monotonic() + (timeout_sec if timeout_sec is not None else 1e9)
        while not future.done() and time.monotonic() < t_end:
            self.spin_once()

    def spin(self):
        raise ExternalShutdownException  # nothing to wait for in tests: behave like Ctrl-C

    def shutdown(self, timeout_sec=None):
        self.nodes = []


def _modules() -> dict[str, types.ModuleType]:
    def mod(name, **attrs):
        m = types.ModuleType(name)
        m.__dict__.update(attrs)
        return m

    q = mod("rclpy.qos")

    class _Policy(enum.Enum):
        @classmethod
        def get_from_short_key(cls, name):
            return cls[name.upper()]

    q.HistoryPolicy = _Policy("HistoryPolicy", "SYSTEM_DEFAULT KEEP_LAST KEEP_ALL")
    q.ReliabilityPolicy = _Policy("ReliabilityPolicy", "SYSTEM_DEFAULT RELIABLE BEST_EFFORT")
    q.DurabilityPolicy = _Policy("DurabilityPolicy", "SYSTEM_DEFAULT TRANSIENT_LOCAL VOLATILE")
    q.QoSProfile = lambda **kw: types.SimpleNamespace(**kw)
    q.qos_profile_parameter_events = q.QoSProfile(depth=1000)
    rclpy = mod(
        "rclpy", init=lambda args=None: None, try_shutdown=lambda: None, ok=lambda: True, qos=q
    )
    return {
        "rclpy": rclpy,
        "rclpy.qos": q,
        "rclpy.node": mod("rclpy.node", Node=Node),
        "rclpy.parameter": mod(
            "rclpy.parameter", Parameter=Parameter, parameter_value_to_python=lambda v: v
        ),
        "rclpy.exceptions": mod("rclpy.exceptions", ParameterException=ParameterException),
        "rclpy.executors": mod(
            "rclpy.executors",
            ExternalShutdownException=ExternalShutdownException,
            SingleThreadedExecutor=SingleThreadedExecutor,
        ),
        "rclpy.task": mod("rclpy.task", Future=Future),
        "rclpy.clock": mod("rclpy.clock", Clock=Clock, ClockType=ClockType),
        "rclpy.duration": mod("rclpy.duration", Duration=Duration),
        "rclpy.parameter_client": mod(
            "rclpy.parameter_client", AsyncParameterClient=AsyncParameterClient
        ),
        "sensor_msgs": mod("sensor_msgs"),
        "sensor_msgs.msg": mod(
            "sensor_msgs.msg", FluidPressure=FluidPressure, JointState=JointState
        ),
        "diagnostic_msgs": mod("diagnostic_msgs"),
        "diagnostic_msgs.msg": mod(
            "diagnostic_msgs.msg",
            DiagnosticArray=DiagnosticArray,
            DiagnosticStatus=DiagnosticStatus,
            KeyValue=KeyValue,
        ),
        "trajectory_msgs": mod("trajectory_msgs"),
        "trajectory_msgs.msg": mod(
            "trajectory_msgs.msg",
            JointTrajectory=JointTrajectory,
            JointTrajectoryPoint=JointTrajectoryPoint,
        ),
        "rosgraph_msgs": mod("rosgraph_msgs"),
        "rosgraph_msgs.msg": mod("rosgraph_msgs.msg", Clock=ClockMsg),
        "std_srvs": mod("std_srvs"),
        "std_srvs.srv": mod("std_srvs.srv", Trigger=Trigger),
        "rcl_interfaces": mod("rcl_interfaces"),
        "rcl_interfaces.msg": mod(
            "rcl_interfaces.msg",
            ParameterDescriptor=ParameterDescriptor,
            FloatingPointRange=FloatingPointRange,
            IntegerRange=IntegerRange,
            SetParametersResult=SetParametersResult,
            ParameterEvent=ParameterEvent,
        ),
    }


NODE_MODULES = (
    "pneu_sim.nodes.sim_node",
    "pneu_control.nodes.controller_node",
    "pneu_control.nodes.logger_node",
    "pneu_driver.nodes.driver_node",
    "pneu_control.nodes.task_node",
)


@contextlib.contextmanager
def installed() -> Iterator[World]:
    """The fake modules in ``sys.modules`` (node modules re-imported against them), then restored."""
    global WORLD
    WORLD = World()
    fakes = _modules()
    names = (*fakes, *NODE_MODULES)
    saved = {k: sys.modules.pop(k) for k in names if k in sys.modules}
    sys.modules.update(fakes)
    try:
        yield WORLD
    finally:
        for k in names:
            sys.modules.pop(k, None)
        sys.modules.update(saved)
