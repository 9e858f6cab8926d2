"""The nidaqmx backend against create_autospec fakes of the real nidaqmx classes.

Only the nidaqmx boundary is faked (Task, System, the stream reader/writer
classes), each with ``spec_set``, so a wrong method name, keyword or attribute
fails here as it would on the rig.
"""

from unittest import mock

import nidaqmx
import nidaqmx.errors
import nidaqmx.stream_readers
import nidaqmx.stream_writers
import nidaqmx.system
import numpy as np
import pytest
from nidaqmx.constants import (
    AcquisitionType,
    AngleUnits,
    DataTransferActiveTransferMode,
    EncoderType,
    TerminalConfiguration,
)
from nidaqmx.system._collections.device_collection import DeviceCollection
from nidaqmx.task import InStream, OutStream, Timing
from nidaqmx.task.channels import AIChannel, AOChannel, CIChannel
from nidaqmx.task.collections import AIChannelCollection, AOChannelCollection, CIChannelCollection
from pneu_driver.daq.errors import DaqIoError, DaqSetupError, DaqUnavailableError, LateCycleError
from pneu_driver.daq.nidaqmx_backend import NidaqmxBackend
from pneu_driver.daq.rig import RigParams
from pneu_driver.daq.scaling import Scaler
from pneu_driver.loop.driver_loop import DriverLoop
from pneu_driver.safety import SafetyParams, SafetySupervisor
from pneu_msgs_py.params.core import with_updates

HWTSP = AcquisitionType.HW_TIMED_SINGLE_POINT
REAL_TASK = nidaqmx.Task  # the class to spec against, captured before any patching


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


class FakeDaq:
    """Autospec'd nidaqmx, patched where the backend looks it up; records every task and write."""

    def __init__(self, monkeypatch, devices=("Dev1",)):
        self.tasks = []
        self.log = []
        self.writes = []  # (u_lin, u_rot) per timed AO write, copied at call time
        self.volts = [2.0, 1.5, 3.0, 2.5]
        self.ticks = 0.0
        self.ai_errors = {}  # read number -> DAQmx code
        self.write_errors = {}
        self.n_ai = self.n_ci = 0
        self.t_ns = 10**9  # a fake monotonic clock: each HW-timed AI read waits one period

        task_cls = mock.create_autospec(REAL_TASK, spec_set=True)
        task_cls.side_effect = self._new_task
        monkeypatch.setattr(nidaqmx, "Task", task_cls)

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
        for name, inst in (
            ("AnalogMultiChannelReader", self.ai_reader),
            ("CounterReader", self.ci_reader),
        ):
            cls = mock.create_autospec(getattr(nidaqmx.stream_readers, name), spec_set=True)
            cls.return_value = inst
            setattr(self, name, cls)
            monkeypatch.setattr(nidaqmx.stream_readers, name, cls)
        self.AnalogMultiChannelWriter = mock.create_autospec(
            nidaqmx.stream_writers.AnalogMultiChannelWriter, spec_set=True
        )
        self.AnalogMultiChannelWriter.return_value = self.writer
        monkeypatch.setattr(
            nidaqmx.stream_writers, "AnalogMultiChannelWriter", self.AnalogMultiChannelWriter
        )

    def clock(self):
        self.t_ns += 1_000
        return self.t_ns

    def _new_task(self, new_task_name="", *, grpc_options=None):
        t = spec(REAL_TASK)
        i = len(self.tasks)
        # the sub-objects behind Task's properties, specced on first use (autospec is slow)
        for name, cls, made in (
            ("ai_channels", AIChannelCollection, ("add_ai_voltage_chan", AIChannel)),
            ("ao_channels", AOChannelCollection, ("add_ao_voltage_chan", AOChannel)),
            ("ci_channels", CIChannelCollection, ("add_ci_ang_encoder_chan", CIChannel)),
            ("timing", Timing, None),
            ("in_stream", InStream, None),
            ("out_stream", OutStream, None),
        ):
            lazy_property(t, name, cls, made)
        t.start.side_effect = lambda: self.log.append(("start", i))
        t.stop.side_effect = lambda: self.log.append(("stop", i))
        t.close.side_effect = lambda: self.log.append(("close", i))
        t.write.side_effect = lambda data, auto_start=None, timeout=10.0: self.log.append(
            ("write_now", i, list(data))
        )
        self.tasks.append(t)
        self.log.append(("task", i))
        return t

    def role(self, t):
        built = type(t).built  # only look at the channel collections the backend used
        if "ai_channels" in built and t.ai_channels.add_ai_voltage_chan.called:
            return "ai"
        if "ci_channels" in built and t.ci_channels.add_ci_ang_encoder_chan.called:
            return "ci"
        return "ao_now" if t.write.called else "ao"

    def task(self, role):
        [t] = [t for t in self.tasks if self.role(t) == role]
        return t

    def _read_ai(self, data, timeout=10):
        self.n_ai += 1
        self.t_ns += 1_000_000
        code = self.ai_errors.get(self.n_ai)
        if code is not None:
            raise nidaqmx.errors.DaqError("DAQmx says no", code)
        data[:] = self.volts

    def _read_ci(self, timeout=10):
        self.n_ci += 1
        return self.ticks

    def _write(self, data, timeout=10):
        code = self.write_errors.get(len(self.writes) + 1)
        self.writes.append(tuple(float(v) for v in data))
        self.log.append(("write_hw", tuple(float(v) for v in data)))
        if code is not None:
            raise nidaqmx.errors.DaqError("DAQmx says late", code)


@pytest.fixture
def daq(monkeypatch):
    return FakeDaq(monkeypatch)


def hw_rig(**over):
    return with_updates(RigParams(), {"loop.rt_priority": 0, **over})


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
    # 2. AI: four voltage channels, RSE, ±10 V, HW-timed single point on the onboard clock
    ai = daq.task("ai")
    assert ai.ai_channels.add_ai_voltage_chan.call_args_list == [
        mock.call(
            f"Dev1/ai{i}",
            name,
            terminal_config=TerminalConfiguration.RSE,
            min_val=-10.0,
            max_val=10.0,
        )
        for i, name in enumerate(("p_c1", "p_c2", "p_m1", "laser"))
    ]
    ai.timing.cfg_samp_clk_timing.assert_called_once_with(1000.0, source="", sample_mode=HWTSP)
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
    # 5. slaves first, the master clock (AI) last; the safe value precedes them
    starts = [e for e in daq.log if e[0] in ("start", "write_hw")]
    idx = {daq.role(t): i for i, t in enumerate(daq.tasks)}
    assert starts == [
        ("write_hw", (5.0, 5.0)),
        ("start", idx["ci"]),
        ("start", idx["ao"]),
        ("start", idx["ai"]),
    ]
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
    idx = {daq.role(t): i for i, t in enumerate(daq.tasks[:4])}
    tail = daq.log[-9:]
    assert tail[:3] == [("stop", idx["ai"]), ("stop", idx["ci"]), ("stop", idx["ao"])]
    assert tail[3:6] == [("close", idx["ai"]), ("close", idx["ci"]), ("close", idx["ao"])]
    assert tail[6:] == [("task", 4), ("write_now", 4, [5.0, 5.0]), ("close", 4)]


def test_late_cycles_are_counted_and_the_loop_goes_on(daq):
    daq.ai_errors = {3: -209800, 4: -209802}
    daq.write_errors = {7: -209801}  # the write of cycle 6 (after the pre-start write)
    loop, _ = run_driver(daq, 8)
    stats = loop.run(8)
    assert stats.cycles == 8 and stats.daq_late_errors == 3 and stats.late_cycles == 3
    assert daq.n_ai == 8
    assert len(daq.writes) == 1 + 8 + 1  # still one write per cycle
    assert daq.writes[-1] == (5.0, 5.0)


def test_a_daq_error_stops_the_loop_with_the_valves_safe(daq):
    daq.ai_errors = {4: -200279}  # not a lateness code: fatal
    loop, _ = run_driver(daq, 20)
    with pytest.raises(DaqIoError, match=r"AI read failed: DAQmx -200279"):
        loop.run(20)
    assert daq.writes[-1] == (5.0, 5.0)
    assert daq.log[-3:] == [("task", 4), ("write_now", 4, [5.0, 5.0]), ("close", 4)]
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


def test_late_read_codes_from_either_reader(daq):
    be = NidaqmxBackend(hw_rig())
    be.open()
    daq.ai_errors = {1: -209802}
    with pytest.raises(LateCycleError) as info:
        be.read()
    assert info.value.codes == (-209802,)
    assert daq.n_ci == 1  # the counter was still read, keeping the two tasks in step
    be.close()


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
