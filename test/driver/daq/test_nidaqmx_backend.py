"""The nidaqmx backend against create_autospec fakes of the real nidaqmx classes.

Only the nidaqmx boundary is faked (Task, System, the stream reader/writer
classes, the task's interpreter), each with ``spec_set``, so a wrong method
name, keyword or attribute fails here as it would on the rig. The C library
behind ``nidaqmx._lib.lib_importer`` is a stand-in for ``libnidaqmx.so``: the
real ``DaqFunctionImporter`` over functions that, like a ``ctypes.CDLL``
function, refuse to be called before their ``argtypes`` are declared and
convert every argument through them.

The fake sample clock behaves like DAQmx HW-timed single point: a read waits
for the next clock; a read that comes after one or more clocks went by
returns the newest sample and -- only when ``DAQmx_RealTime_ReportMissedSamp``
was set on the task and after the warm-up iterations (NI's default 100, or
``NumOfWarmupIters``) -- raises -209800
(-201027 for 3 or more missed clocks). A timed AO write for clock k+1 made
after clock k+1 raises -209801 (HW-timed output; not governed by
ReportMissedSamp -- unverified, NI documents that attribute for Read only).
"""

import ctypes
from pathlib import Path
from unittest import mock

import nidaqmx
import nidaqmx._lib
import nidaqmx.errors
import nidaqmx.stream_readers
import nidaqmx.stream_writers
import nidaqmx.system
import numpy as np
import pytest
from nidaqmx._library_interpreter import LibraryInterpreter
from nidaqmx.constants import (
    AcquisitionType,
    AngleUnits,
    DataTransferActiveTransferMode,
    EncoderType,
    LineGrouping,
    TerminalConfiguration,
)
from nidaqmx.system._collections.device_collection import DeviceCollection
from nidaqmx.task import InStream, OutStream, Timing
from nidaqmx.task.channels import AIChannel, AOChannel, CIChannel, DOChannel
from nidaqmx.task.collections import (
    AIChannelCollection,
    AOChannelCollection,
    CIChannelCollection,
    DOChannelCollection,
)
from pneu_driver.daq.errors import DaqIoError, DaqSetupError, DaqUnavailableError
from pneu_driver.daq.nidaqmx_backend import NidaqmxBackend
from pneu_driver.daq.rig import RigParams, load_rig_params
from pneu_driver.daq.scaling import Scaler
from pneu_driver.loop.driver_loop import DriverLoop
from pneu_driver.safety import SafetyParams, SafetySupervisor
from pneu_msgs_py.params.core import with_updates

HWTSP = AcquisitionType.HW_TIMED_SINGLE_POINT
REAL_TASK = nidaqmx.Task  # the class to spec against, captured before any patching
T_NS = 1_000_000
WARMUP = 100  # DAQmx_RealTime_NumOfWarmupIters default: no lateness reported before


def spec(cls):
    return mock.create_autospec(cls, instance=True, spec_set=True)


def lazy_property(mock_obj, name, cls, made=None):
    """``mock_obj.name`` becomes a spec_set autospec of ``cls``, built on first access."""
    kind = type(mock_obj)  # every mock instance has a class of its own
    if "built" not in kind.__dict__:
        kind.built = {}

    def get(self):
        if name not in kind.built:
            sub = spec(cls)
            if made is not None:
                getattr(sub, made[0]).return_value = spec(made[1])
            kind.built[name] = sub
        return kind.built[name]

    setattr(kind, name, property(get))


class CFunction:
    """A C function as ``ctypes.CDLL`` hands it out: ``argtypes`` None until declared."""

    def __init__(self, name, impl):
        self.name, self.impl = name, impl
        self.argtypes = None
        self.restype = ctypes.c_int

    def __call__(self, *args):
        if self.argtypes is None:
            raise TypeError(f"{self.name}: argtypes not declared (ctypes would guess the C types)")
        if len(args) != len(self.argtypes):
            raise TypeError(f"{self.name}: {len(args)} arguments, {len(self.argtypes)} declared")
        conv = []
        for t, a in zip(self.argtypes, args, strict=True):
            t.from_param(a)  # raises TypeError for a wrong Python type, as ctypes does
            conv.append(a if isinstance(a, t) else t(a))
        return self.impl(*conv)


class FakeLib:
    """The part of libnidaqmx.so the backend calls directly (Real-Time attributes)."""

    def __init__(self, daq):
        self.DAQmxSetRealTimeReportMissedSamp = CFunction(
            "DAQmxSetRealTimeReportMissedSamp", daq._set_report_missed_samp
        )
        self.DAQmxSetRealTimeNumOfWarmupIters = CFunction(
            "DAQmxSetRealTimeNumOfWarmupIters", daq._set_warmup
        )


class FakeDaq:
    """Autospec'd nidaqmx, patched where the backend looks it up; records every task and write."""

    def __init__(self, monkeypatch, devices=("Dev1",)):
        self.tasks = []
        self.log = []
        self.writes = []  # (u_lin, u_rot) per timed AO write, copied at call time
        self.heartbeat = []  # every DO level written
        self.volts = [2.0, 1.5, 3.0, 2.5]
        self.ticks = 0.0
        self.ai_errors = {}  # read number -> DAQmx code (errors other than lateness)
        self.write_errors = {}
        self.report_missed = {}  # task handle value -> ReportMissedSamp
        self.warmup = {}  # task handle value -> NumOfWarmupIters (DAQmx default: WARMUP)
        self.keep_default_warmup = False  # True: as if the backend had not set it
        self.stall_after_write = {}  # timed write number -> ns the program stalls after it
        self.n_ai = self.n_ci = 0
        self.t_ns = 10**9  # a fake monotonic clock (the loop's clock_ns)
        self.t0_ns = None  # when the AI task (the sample clock) started
        self.next_tick = 1  # index of the next sample clock a read will return
        self.late_raised = []
        self._by_role = {}

        task_cls = mock.create_autospec(REAL_TASK, spec_set=True)
        task_cls.side_effect = self._new_task
        monkeypatch.setattr(nidaqmx, "Task", task_cls)
        importer = nidaqmx._lib.DaqFunctionImporter(FakeLib(self))
        monkeypatch.setattr(nidaqmx._lib.lib_importer, "_windll", importer)
        monkeypatch.setattr(nidaqmx._lib.lib_importer, "_cdll", importer)

        self.devices = spec(DeviceCollection)
        self.devices.device_names = list(devices)
        system = spec(nidaqmx.system.System)
        system.devices = self.devices
        self.system_cls = mock.create_autospec(nidaqmx.system.System, spec_set=True)
        self.system_cls.local.return_value = system
        monkeypatch.setattr(nidaqmx.system, "System", self.system_cls)

        self.ai_reader = spec(nidaqmx.stream_readers.AnalogMultiChannelReader)
        self.ai_reader.read_one_sample.side_effect = self._read_ai
        self.ci_reader = spec(nidaqmx.stream_readers.CounterReader)
        self.ci_reader.read_one_sample_double.side_effect = self._read_ci
        self.writer = spec(nidaqmx.stream_writers.AnalogMultiChannelWriter)
        self.writer.write_one_sample.side_effect = self._write
        self.do_writer = spec(nidaqmx.stream_writers.DigitalSingleChannelWriter)
        self.do_writer.write_one_sample_one_line.side_effect = self._write_do
        for module, name, inst in (
            (nidaqmx.stream_readers, "AnalogMultiChannelReader", self.ai_reader),
            (nidaqmx.stream_readers, "CounterReader", self.ci_reader),
            (nidaqmx.stream_writers, "AnalogMultiChannelWriter", self.writer),
            (nidaqmx.stream_writers, "DigitalSingleChannelWriter", self.do_writer),
        ):
            cls = mock.create_autospec(getattr(module, name), spec_set=True)
            cls.return_value = inst
            setattr(self, name, cls)
            monkeypatch.setattr(module, name, cls)

    def clock(self):
        self.t_ns += 1_000
        return self.t_ns

    @property
    def interpreter(self):
        """One autospec'd LibraryInterpreter for every task (it holds no state); its
        ``check_for_error`` is the real one: < 0 raises, > 0 warns."""
        if "_interp" not in self.__dict__:
            interp = spec(LibraryInterpreter)
            interp.get_extended_error_info.return_value = "DAQmx extended error info"
            interp.check_for_error.side_effect = lambda code, **kw: (
                LibraryInterpreter.check_for_error(interp, code, **kw)
            )
            self._interp = interp
        return self._interp

    def _new_task(self, new_task_name="", *, grpc_options=None):
        t = spec(REAL_TASK)
        i = len(self.tasks)
        # the sub-objects behind Task's properties, specced on first use (autospec is slow)
        for name, cls, made in (
            ("ai_channels", AIChannelCollection, ("add_ai_voltage_chan", AIChannel)),
            ("ao_channels", AOChannelCollection, ("add_ao_voltage_chan", AOChannel)),
            ("ci_channels", CIChannelCollection, ("add_ci_ang_encoder_chan", CIChannel)),
            ("do_channels", DOChannelCollection, ("add_do_chan", DOChannel)),
            ("timing", Timing, None),
            ("in_stream", InStream, None),
            ("out_stream", OutStream, None),
        ):
            lazy_property(t, name, cls, made)
        t._handle = nidaqmx._lib.TaskHandle(0x1000 + i)
        t._interpreter = self.interpreter
        t.start.side_effect = lambda: self._start(i)
        t.stop.side_effect = lambda: self.log.append(("stop", i))
        t.close.side_effect = lambda: self.log.append(("close", i))
        t.write.side_effect = lambda data, auto_start=None, timeout=10.0: self.log.append(
            ("write_now", i, list(data))
        )
        self.tasks.append(t)
        self.log.append(("task", i))
        return t

    def _start(self, i):
        self.log.append(("start", i))
        if self.role(self.tasks[i]) == "ai" and self.timed("ai"):
            self.t0_ns = self.t_ns  # the sample clock runs from here

    def _set_report_missed_samp(self, handle, enable):
        self.report_missed[handle.value] = enable.value
        self.log.append(("report_missed", handle.value, enable.value))
        return 0

    def _set_warmup(self, handle, n):
        if not self.keep_default_warmup:
            self.warmup[handle.value] = n.value
        return 0

    def role(self, t):
        built = type(t).built  # only look at the channel collections the backend used
        if "ai_channels" in built and t.ai_channels.add_ai_voltage_chan.called:
            return "ai"
        if "ci_channels" in built and t.ci_channels.add_ci_ang_encoder_chan.called:
            return "ci"
        if "do_channels" in built and t.do_channels.add_do_chan.called:
            return "do"
        return "ao_now" if t.write.called else "ao"

    def task(self, role):
        if role in self._by_role:  # a task's role is fixed once its channels exist
            return self._by_role[role]
        [t] = [t for t in self.tasks if self.role(t) == role]
        if role != "ao":  # "ao" is also what a task without channels looks like
            self._by_role[role] = t
        return t

    def timed(self, role):
        return "timing" in type(self.task(role)).built and (
            self.task(role).timing.cfg_samp_clk_timing.called
        )

    def _read_ai(self, data, timeout=10):
        self.n_ai += 1
        code = self.ai_errors.get(self.n_ai)
        if code is not None:
            raise nidaqmx.errors.DaqReadError("DAQmx says no", code, 0)
        data[:] = self.volts
        if self.t0_ns is None:  # on demand: no clock
            return
        due = self.t0_ns + self.next_tick * T_NS
        missed = 0
        if self.t_ns < due:
            self.t_ns = due  # HW-timed single point: wait for the clock
        else:  # clocks went by: the newest sample, the others are lost
            newest = (self.t_ns - self.t0_ns) // T_NS
            missed = newest - self.next_tick
            self.next_tick = newest
        self.next_tick += 1
        ai = self.task("ai")
        warmup = self.warmup.get(ai._handle.value, WARMUP)
        if missed and self.report_missed.get(ai._handle.value) and self.n_ai > warmup:
            code = -201027 if missed >= 3 else -209800
            self.late_raised.append((self.n_ai, code))
            ai._interpreter.check_for_error(code, samps_per_chan_read=1)

    def _read_ci(self, timeout=10):
        self.n_ci += 1
        return self.ticks

    def _write(self, data, timeout=10):
        n = len(self.writes) + 1
        code = self.write_errors.get(n)
        self.writes.append(tuple(float(v) for v in data))
        self.log.append(("write_hw", tuple(float(v) for v in data)))
        if code is not None:
            raise nidaqmx.errors.DaqWriteError("DAQmx says no", code, 0)
        late = self.t0_ns is not None and self.t_ns >= self.t0_ns + self.next_tick * T_NS
        self.t_ns += self.stall_after_write.get(n, 0)
        if late and self.timed("ao"):  # the value missed its clock (k+1)
            self.late_raised.append(("write", -209801))
            self.task("ao")._interpreter.check_for_error(-209801, samps_per_chan_written=0)

    def _write_do(self, data, timeout=10):
        self.heartbeat.append(bool(data))


@pytest.fixture
def daq(monkeypatch):
    return FakeDaq(monkeypatch)


def hw_rig(**over):
    return with_updates(
        RigParams(), {"loop.rt_priority": 0, "loop.switch_interval_us": 0.0, **over}
    )


def test_open_hardware_timed_channels_scaling_and_order(daq):
    be = NidaqmxBackend(hw_rig())
    be.open()
    assert be.hardware_paced and be.is_open
    # 1. valves safe on demand before any timed task exists, in a task that is then closed
    assert daq.log[:4] == [("task", 0), ("write_now", 0, [5.0, 5.0]), ("close", 0), ("task", 1)]
    now = daq.tasks[0]
    assert now.ao_channels.add_ao_voltage_chan.call_args_list == [
        mock.call("Dev1/ao0", "valve_linear", min_val=0.0, max_val=10.0),
        mock.call("Dev1/ao1", "valve_rotary", min_val=0.0, max_val=10.0),
    ]
    now.write.assert_called_once_with([5.0, 5.0], auto_start=True, timeout=1.0)
    # 2. AI: four voltage channels, differential, ±10 V, HW-timed single point on the onboard
    #    clock, missed-sample reporting on this task's handle (through nidaqmx's library handle)
    ai = daq.task("ai")
    assert ai.ai_channels.add_ai_voltage_chan.call_args_list == [
        mock.call(
            f"Dev1/ai{i}",
            name,
            terminal_config=TerminalConfiguration.DIFF,
            min_val=-10.0,
            max_val=10.0,
        )
        for i, name in enumerate(("p_c1", "p_c2", "p_m1", "laser"))
    ]
    ai.timing.cfg_samp_clk_timing.assert_called_once_with(1000.0, source="", sample_mode=HWTSP)
    assert daq.report_missed == {ai._handle.value: True}
    assert daq.warmup == {ai._handle.value: 0}  # reported from the first cycle
    idx_ai = daq.tasks.index(ai)
    assert daq.log.index(("report_missed", ai._handle.value, True)) < daq.log.index(
        ("start", idx_ai)
    )
    # 3. CI: X4 angular encoder in ticks, programmed I/O, on the AI sample clock
    ci = daq.task("ci")
    ci.ci_channels.add_ci_ang_encoder_chan.assert_called_once_with(
        "Dev1/ctr0",
        "encoder",
        decoding_type=EncoderType.X_4,
        zidx_enable=False,
        units=AngleUnits.TICKS,
        pulses_per_rev=1000,
        initial_angle=0.0,
    )
    chan = ci.ci_channels.add_ci_ang_encoder_chan.return_value
    assert chan.ci_data_xfer_mech == DataTransferActiveTransferMode.POLLED
    for phase in ("a", "b"):  # rig.yaml encoder.dig_filter: 125ns on both quadrature inputs
        assert getattr(chan, f"ci_encoder_{phase}_input_dig_fltr_enable") is True
        assert getattr(chan, f"ci_encoder_{phase}_input_dig_fltr_min_pulse_width") == 125e-9
    ci.timing.cfg_samp_clk_timing.assert_called_once_with(
        1000.0, source="/Dev1/ai/SampleClock", sample_mode=HWTSP
    )
    # 4. AO: two channels on the AI sample clock, the safe value written before the start
    ao = daq.task("ao")
    assert ao.ao_channels.add_ao_voltage_chan.call_count == 2
    ao.timing.cfg_samp_clk_timing.assert_called_once_with(
        1000.0, source="/Dev1/ai/SampleClock", sample_mode=HWTSP
    )
    daq.AnalogMultiChannelWriter.assert_called_once_with(ao.out_stream, auto_start=False)
    daq.AnalogMultiChannelReader.assert_called_once_with(ai.in_stream)
    daq.CounterReader.assert_called_once_with(ci.in_stream)
    # 5. heartbeat: one on-demand DO line, started and written low before the clock runs
    do = daq.task("do")
    do.do_channels.add_do_chan.assert_called_once_with(
        "Dev1/port0/line0", "heartbeat", line_grouping=LineGrouping.CHAN_PER_LINE
    )
    do.timing.cfg_samp_clk_timing.assert_not_called()
    daq.DigitalSingleChannelWriter.assert_called_once_with(do.out_stream, auto_start=False)
    assert daq.heartbeat == [False]
    # no per-call array-shape query in the hot loop
    for rw in (daq.ai_reader, daq.ci_reader, daq.writer, daq.do_writer):
        assert rw.verify_array_shape is False
    # 6. slaves first, the master clock (AI) last; the safe value precedes them
    starts = [e for e in daq.log if e[0] in ("start", "write_hw")]
    idx = {daq.role(t): i for i, t in enumerate(daq.tasks)}
    assert starts == [
        ("start", idx["do"]),
        ("write_hw", (5.0, 5.0)),
        ("start", idx["ci"]),
        ("start", idx["ao"]),
        ("start", idx["ai"]),
    ]
    be.close()


def test_terminal_configuration_from_yaml_reaches_add_ai_voltage_chan(daq, tmp_path):
    text = Path(load_rig_params.__code__.co_filename).parents[4] / "config" / "rig.yaml"
    yaml_text = text.read_text(encoding="utf-8")
    old = "    p_c1: DIFF"
    assert old in yaml_text  # the project's file: DIFF by default
    yaml_text = yaml_text.replace(old, "    p_c1: NRSE").replace(
        "    laser: DIFF", "    laser: RSE"
    )
    (tmp_path / "rig.yaml").write_text(yaml_text, encoding="utf-8")
    rig = with_updates(load_rig_params(tmp_path / "rig.yaml"), {"loop.switch_interval_us": 0.0})
    be = NidaqmxBackend(rig)
    be.open()
    calls = daq.task("ai").ai_channels.add_ai_voltage_chan.call_args_list
    assert [c.kwargs["terminal_config"] for c in calls] == [
        TerminalConfiguration.NRSE,
        TerminalConfiguration.DIFF,
        TerminalConfiguration.DIFF,
        TerminalConfiguration.RSE,
    ]
    assert [c.args[0] for c in calls] == ["Dev1/ai0", "Dev1/ai1", "Dev1/ai2", "Dev1/ai3"]
    be.close()


def test_software_timing_configures_no_sample_clock(daq):
    be = NidaqmxBackend(hw_rig(**{"loop.timing": "software"}))
    be.open()
    assert not be.hardware_paced
    for t in daq.tasks:
        t.timing.cfg_samp_clk_timing.assert_not_called()
    ci = daq.task("ci")
    assert (
        ci.ci_channels.add_ci_ang_encoder_chan.return_value.ci_data_xfer_mech
        != DataTransferActiveTransferMode.POLLED
    )
    assert all(daq.tasks[i].start.called for i in range(1, 4))  # started once, not per write
    be.close()


def test_on_demand_ci_and_ao_beside_a_timed_ai(daq):
    be = NidaqmxBackend(hw_rig(**{"loop.ci_timing": "on_demand", "loop.ao_timing": "on_demand"}))
    be.open()
    daq.task("ai").timing.cfg_samp_clk_timing.assert_called_once()
    daq.task("ci").timing.cfg_samp_clk_timing.assert_not_called()
    daq.task("ao").timing.cfg_samp_clk_timing.assert_not_called()
    be.close()


def test_read_returns_volts_and_unwrapped_counts(daq):
    be = NidaqmxBackend(hw_rig())
    be.open()
    daq.ticks = float(2**32 - 6)  # the register read unsigned after turning 6 counts backwards
    raw = be.read()
    assert raw.volts == (2.0, 1.5, 3.0, 2.5) and raw.counts == -6
    daq.ticks = 5.0
    assert be.read().counts == 5
    s = Scaler(be.rig).sample(0, 0, raw)
    assert s.p_c1 == pytest.approx(301325.0) and s.x == pytest.approx(0.0)
    args = daq.ai_reader.read_one_sample.call_args
    assert (
        isinstance(args.args[0], np.ndarray)
        and args.args[0].shape == (4,)
        and args.kwargs == {"timeout": 0.1}
    )
    daq.ci_reader.read_one_sample_double.assert_called_with(timeout=0.1)
    be.write(7.25, float("nan"))  # NaN never reaches the DAQ; the clamp is the last line of defence
    be.write(12.0, -3.0)
    assert daq.writes[-2:] == [(7.25, 5.0), (10.0, 0.0)]
    be.close()


def run_driver(daq, n, rig=None, **kw):
    rig = rig or hw_rig()
    sup = SafetySupervisor(SafetyParams(), rig.period_s)
    loop = None

    def controller(s):
        loop.put_command("linear", 6.0 + 0.1 * (s.k % 5), s.stamp_ns)
        loop.put_command("rotary", 4.0, s.stamp_ns)

    loop = DriverLoop(NidaqmxBackend(rig), rig, sup, on_sample=controller, clock_ns=daq.clock, **kw)
    return loop, controller


def test_one_read_and_one_write_per_cycle_then_safe_on_shutdown(daq):
    loop, _ = run_driver(daq, 5)
    daq.volts = [2.0, 1.5, 3.0, 2.5]
    stats = loop.run(5)
    assert stats.cycles == 5
    assert daq.n_ai == 5 and daq.n_ci == 5
    # pre-start safe value, one write per cycle (the command for the next clock), the shutdown's safe value
    assert daq.writes[0] == (5.0, 5.0)
    assert daq.writes[1:6] == [(6.0 + 0.1 * (k % 5), 4.0) for k in range(5)]
    assert daq.writes[6:] == [(5.0, 5.0)]
    # every task stopped and closed (AI, the clock, first), then the on-demand safe write
    timed = [daq.tasks.index(daq.task(r)) for r in ("ai", "ci", "ao", "do")]
    n = len(timed)
    tail = daq.log[-(2 * n + 3) :]
    assert tail[:n] == [("stop", i) for i in timed]
    assert tail[n : 2 * n] == [("close", i) for i in timed]
    last = len(daq.tasks) - 1
    assert tail[2 * n :] == [("task", last), ("write_now", last, [5.0, 5.0]), ("close", last)]


def test_heartbeat_toggles_every_cycle_and_stops_when_the_loop_stops(daq):
    loop, _ = run_driver(daq, 6)
    stats = loop.run(6)
    # low at open, one edge per cycle, low at shutdown; nothing after the DO task closed
    assert daq.heartbeat == [False, True, False, True, False, True, False, False]
    assert stats.heartbeats == 6
    assert daq.log.index(("close", daq.tasks.index(daq.task("do")))) > daq.log.index(
        ("stop", daq.tasks.index(daq.task("ai")))
    )


def test_heartbeat_stops_while_tripped_and_resumes_after_reset(daq):
    loop, controller = run_driver(daq, 12)

    def operator(s):
        controller(s)
        if s.k == 3:
            loop.estop("operator")
        if s.k == 7:
            assert loop.reset()[0]

    loop._on_sample = operator
    loop.run(12)
    # edges at cycles 0-2, none while the e-stop is latched (3-6), again from 7
    edges = daq.heartbeat[1:-1]
    assert edges == [True, False, True, *[False, True, False, True, False]]
    assert daq.heartbeat[-1] is False


def test_heartbeat_off_in_rig_yaml_creates_no_do_task(daq):
    be = NidaqmxBackend(hw_rig(**{"heartbeat.enabled": False}))
    be.open()
    assert all(daq.role(t) != "do" for t in daq.tasks)
    be.heartbeat(True)  # a no-op
    daq.DigitalSingleChannelWriter.assert_not_called()
    be.close()


def stall_at(daq, controller, k_stall, ns):
    """The loop's controller callback, stalling ``ns`` (on the fake clock) at sample ``k_stall``."""

    def stalled(s):
        controller(s)
        if s.k == k_stall:
            daq.t_ns += ns

    return stalled


def test_a_3ms_stall_is_counted_late_with_missed_sample_reporting(daq):
    """The loop's own work stalls 3 ms in cycle 150 (after NI's 100 warm-up iterations)."""
    loop, controller = run_driver(daq, 160)
    loop._on_sample = stall_at(daq, controller, 150, 3_000_000)
    stats = loop.run(160)
    # the write of cycle 150 missed clock 151, the next read found 151 and 152 gone
    assert daq.late_raised == [("write", -209801), (152, -209800)]
    assert stats.daq_late_errors == 2 and stats.late_codes == {-209801: 1, -209800: 1}
    assert stats.late_cycles == 2 and stats.missed_ticks == 2
    assert stats.cycles == 160 and daq.n_ai == 160
    # the sample index follows the clock across the gap: the last read returned clock 162
    assert loop.last_sample.k == 161 and daq.next_tick == 163
    diag = loop.diagnostics()
    assert diag["daq_late_errors"] == "2" and diag["daq_late_codes"] == "-209801:1 -209800:1"


@pytest.mark.parametrize("report", [True, False])
def test_a_stall_after_the_write_is_seen_only_with_reporting_on(daq, report):
    """The program stalls 3 ms after its write (a GC pause, a page fault): the write was in
    time, only the next read can tell that clocks were missed -- and DAQmx says so only
    when ReportMissedSamp is on. Off, the loop takes the newest sample for the next one:
    its own clock sees one slow cycle, but no missed tick, and from then on its sample
    index (and every stamp) is two clocks behind the card."""
    daq.stall_after_write = {2 + 150: 3_000_000}  # write 1 is the pre-start one, 2 is cycle 0's
    rig = hw_rig(**{"loop.report_missed_samples": report})
    loop, _ = run_driver(daq, 160, rig=rig)
    stats = loop.run(160)
    assert stats.late_cycles == 1
    if report:
        assert daq.report_missed  # set on the AI task
        assert daq.late_raised == [(152, -209800)]
        assert stats.late_codes == {-209800: 1} and stats.missed_ticks == 2
        assert loop.last_sample.k == daq.next_tick - 2  # sample k is clock k + 1
    else:
        assert daq.report_missed == {}  # never set: DAQmx's default (off)
        assert daq.late_raised == [] and stats.daq_late_errors == 0 and stats.missed_ticks == 0
        assert loop.last_sample.k == daq.next_tick - 2 - 2  # two clocks lost, unseen


@pytest.mark.parametrize("warmup_off", [True, False])
def test_lateness_from_the_first_cycle_with_the_warmup_off(daq, warmup_off):
    """NI's 100 warm-up iterations would let a stall at cycle 50 shift every later sample
    index unseen; the backend sets them to 0."""
    daq.keep_default_warmup = not warmup_off  # what DAQmx does with its default
    loop, controller = run_driver(daq, 60)
    loop._on_sample = stall_at(daq, controller, 50, 3_000_000)
    stats = loop.run(60)
    reads = [c for c in daq.late_raised if c[0] != "write"]
    assert reads == ([(52, -209800)] if warmup_off else [])
    assert stats.missed_ticks == (2 if warmup_off else 0)


def test_a_driver_without_the_real_time_entry_point_is_a_setup_error(daq, monkeypatch):
    monkeypatch.setattr(
        nidaqmx._lib.lib_importer, "_windll", nidaqmx._lib.DaqFunctionImporter(object())
    )
    with pytest.raises(DaqSetupError, match=r"report_missed_samples: false"):
        NidaqmxBackend(hw_rig()).open()
    assert all(t.close.called for t in daq.tasks)


def test_a_daq_error_stops_the_loop_with_the_valves_safe(daq):
    daq.ai_errors = {4: -200279}  # not a lateness code: fatal
    loop, _ = run_driver(daq, 20)
    with pytest.raises(DaqIoError, match=r"AI read failed: DAQmx -200279"):
        loop.run(20)
    assert daq.writes[-1] == (5.0, 5.0)
    last = len(daq.tasks) - 1
    assert daq.log[-3:] == [("task", last), ("write_now", last, [5.0, 5.0]), ("close", last)]
    assert all(t.close.called for t in daq.tasks)


def test_safe_value_even_when_the_timed_write_fails_at_shutdown(daq, caplog):
    loop, _ = run_driver(daq, 3)
    daq.write_errors = {5: -50405}  # the shutdown's timed write fails (device gone)
    loop.run(3)
    assert "writing the safe value at shutdown failed" in caplog.text and "-50405" in caplog.text
    assert daq.log[-2:] == [
        ("write_now", len(daq.tasks) - 1, [5.0, 5.0]),
        ("close", len(daq.tasks) - 1),
    ]


def test_no_driver_is_one_clear_error_naming_the_device(daq):
    daq.system_cls.local.side_effect = nidaqmx.errors.DaqNotFoundError("libnidaqmx.so not found")
    with pytest.raises(DaqUnavailableError) as info:
        NidaqmxBackend(hw_rig()).open()
    msg = str(info.value)
    assert (
        "NI-DAQmx driver not found" in msg
        and "'Dev1'" in msg
        and msg.endswith("devices visible: none")
    )
    assert "\n" not in msg
    assert daq.tasks == []
    assert not isinstance(nidaqmx.errors.DaqNotFoundError("x"), nidaqmx.errors.DaqError)


def test_missing_device_lists_the_visible_ones(daq):
    daq.devices.device_names = ["Dev2", "PXI1Slot3"]
    with pytest.raises(
        DaqUnavailableError,
        match=r"^DAQ device 'Dev1' not found; devices visible: Dev2, PXI1Slot3$",
    ):
        NidaqmxBackend(hw_rig()).open()
    assert daq.tasks == []


def test_unsupported_timing_is_a_setup_error_and_cleans_up(daq):
    orig = daq._new_task

    def new_task(*a, **k):
        t = orig(*a, **k)
        t.ci_channels.add_ci_ang_encoder_chan.side_effect = lambda *aa, **kk: (_ for _ in ()).throw(
            nidaqmx.errors.DaqError("Counter HW-timed single point needs programmed I/O", -200842)
        )
        return t

    daq._new_task = new_task
    nidaqmx.Task.side_effect = new_task
    with pytest.raises(
        DaqSetupError, match=r"creating the encoder \(CI\) task failed: DAQmx -200842.*on_demand"
    ):
        NidaqmxBackend(hw_rig()).open()
    assert all(t.close.called for t in daq.tasks)
    assert daq.log[-2:] == [
        ("write_now", len(daq.tasks) - 1, [5.0, 5.0]),
        ("close", len(daq.tasks) - 1),
    ]


def test_pre_start_write_refused_is_not_fatal(daq, caplog):
    daq.write_errors = {1: -200292}
    be = NidaqmxBackend(hw_rig())
    be.open()
    assert be.is_open and "pre-start AO write refused" in caplog.text
    assert daq.log[1] == ("write_now", 0, [5.0, 5.0])  # the on-demand safe value came first
    be.close()


def test_probe_exit_codes(daq, capsys):
    from pneu_driver.cli import probe

    assert probe.main([]) == 0
    assert "Dev1: present" in capsys.readouterr().out
    daq.devices.device_names = ["Dev7"]
    assert probe.main([]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'Dev1' not found; devices visible: Dev7" in err
    daq.system_cls.local.side_effect = nidaqmx.errors.DaqNotFoundError("no libnidaqmx")
    assert probe.main(["--device", "Dev3"]) == 1
    assert "driver not found" in capsys.readouterr().err


def test_probe_on_this_machine_names_the_missing_device(capsys):
    """Unpatched nidaqmx: no driver here (or no such device on a rig PC): one line, exit 1."""
    from pneu_driver.cli import probe

    assert probe.main(["--device", "NoSuchDev42"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'NoSuchDev42'" in err and "devices visible:" in err
