"""The real rig through nidaqmx (NI PCI-6221): HW-timed single point at 1 kHz, a heartbeat line.

Call sequence (``open``):

1. ``nidaqmx.system.System.local().devices.device_names`` -- the device must
   be visible (``DaqNotFoundError``, raised when the NI driver is missing, is
   not a ``DaqError``: both become :class:`~pneu_driver.daq.errors.DaqUnavailableError`,
   which names the device and lists the visible ones).
2. Valves safe first: a throw-away on-demand AO task writes 5 V to both valves
   (``Task.write([5.0, 5.0], auto_start=True)``) and is closed; the AO keeps the value.
3. AI task: four ``ai_channels.add_ai_voltage_chan(phys, name, terminal_config,
   min_val, max_val)``, the terminal configuration per sensor from
   ``ai.terminal`` (DIFF by default); hardware timing: ``timing.cfg_samp_clk_timing(rate,
   sample_mode=HW_TIMED_SINGLE_POINT)`` on the onboard clock (the master), and
   ``DAQmx_RealTime_ReportMissedSamp`` on (``loop.report_missed_samples``), so
   that a read that missed sample clocks raises instead of silently returning,
   from the first cycle (``DAQmx_RealTime_NumOfWarmupIters`` 0; NI's default
   100 lets the first 0.1 s go unreported).
   nidaqmx-python does not wrap the Real-Time attributes: the setter is called
   through nidaqmx's own library handle (``nidaqmx._lib.lib_importer``; a
   private API, hence the pin ``nidaqmx>=1.7,<1.8``) on the task's handle, and
   its status goes through the task's ``check_for_error`` like any wrapped call.
4. CI task: ``ci_channels.add_ci_ang_encoder_chan(counter, "encoder",
   decoding_type=X_4, zidx_enable=False, units=AngleUnits.TICKS,
   pulses_per_rev=ppr, initial_angle=0.0)``; A and B digital filters
   (``ci_encoder_{a,b}_input_dig_fltr_enable`` / ``..._min_pulse_width``,
   ``encoder.dig_filter``); on the sample clock: programmed I/O
   (``ci_data_xfer_mech = POLLED``, else DAQmx -200842) and
   ``cfg_samp_clk_timing(rate, source="/Dev1/ai/SampleClock", sample_mode=HW_TIMED_SINGLE_POINT)``.
5. AO task: two ``ao_channels.add_ao_voltage_chan(phys, name, min_val=0, max_val=10)``;
   on the sample clock: ``cfg_samp_clk_timing(rate, source="/Dev1/ai/SampleClock", ...)``,
   so a value written after reading sample k is emitted at clock k+1. The safe
   value is written once more before the task starts (if DAQmx refuses a write
   to an unstarted HW-timed single-point task, that is logged and ignored: the
   on-demand value of step 2 holds).
6. Heartbeat task (``heartbeat.enabled``): one on-demand DO line
   (``do_channels.add_do_chan(line, "heartbeat", line_grouping=CHAN_PER_LINE)``),
   written low and started; ``heartbeat(level)`` is one
   ``DigitalSingleChannelWriter.write_one_sample_one_line`` (one DAQmx call).
   On demand, not clocked: a loop that stops calling leaves the line still.
7. Start CI and AO (slaves), then AI (its clock starts them all).

Every stream reader/writer has ``verify_array_shape = False`` (the buffers are
preallocated with the right shape; True costs one driver query per call).

Per cycle: ``AnalogMultiChannelReader.read_one_sample(buf, timeout)`` (blocks
until the next sample clock in HW-timed single point), ``CounterReader.read_one_sample_double(timeout)``,
``AnalogMultiChannelWriter.write_one_sample(buf, timeout)`` and the heartbeat
write. The late-cycle codes in :data:`LATE_CODES` become
:class:`~pneu_driver.daq.errors.LateCycleError` (counted, not fatal); any other
DAQmx error is fatal.

``close``: stop AI (the clock) then the others, close all, then the on-demand
safe write again, so the valves end at 5 V even if the timed AO never emitted
its last value.

What the card does when this process cannot run ``close`` (killed, crashed,
hung): M Series AO keep their last value and the DO line its last level; after
a device reset or power-up the AO go to 0 V -- a fully open MPYE. Only the
external interlock on the heartbeat makes that safe (docs/rig.md, "Safety on the
real rig").
"""

from __future__ import annotations

import ctypes
import logging
from typing import Any

import numpy as np

from pneu_driver.daq.errors import DaqIoError, DaqSetupError, DaqUnavailableError, LateCycleError
from pneu_driver.daq.rig import AI_SENSORS, DIG_FILTERS, RigParams
from pneu_driver.daq.scaling import RawSample, ao_volts, unwrap_counts

__all__ = [
    "NidaqmxBackend",
    "LATE_CODES",
    "set_report_missed_samp",
    "set_warmup_iterations",
    "visible_devices",
]

log = logging.getLogger("pneu_driver.nidaqmx")

# DAQmx status codes of a HW-timed single-point loop that missed its clock (nidaqmx error_codes):
# -209800 Read not complete before the next sample clock (reported with ReportMissedSamp on),
# -209801 Write not complete before the next sample clock (HW-timed output),
# -209802 / -209803 WaitForNextSampleClock saw 1 / 3 or more missed clocks,
# -201027 WaitForNextSampleClock or Read saw 3 or more missed clocks (ReportMissedSamp on).
LATE_CODES = frozenset({-209800, -209801, -209802, -209803, -201027})


def _import_nidaqmx(device: str) -> Any:
    try:
        import nidaqmx
        import nidaqmx.constants
        import nidaqmx.errors
        import nidaqmx.stream_readers
        import nidaqmx.stream_writers
        import nidaqmx.system
        from nidaqmx import _lib  # noqa: F401  (private: the Real-Time attribute setter)
    except ImportError as err:
        raise DaqUnavailableError(
            device,
            (),
            f"the nidaqmx Python package is not installed ({err}); cannot open DAQ device {device!r}",
        ) from err
    return nidaqmx


def _set_real_time(nidaqmx: Any, task: Any, name: str, c_type: Any, value: Any) -> None:
    """``DAQmxSetRealTime<name>(task, value)`` through nidaqmx's own library handle.

    The Real-Time attributes are not wrapped by nidaqmx-python (its code
    generator skips them); this is the ctypes pattern of its generated setters,
    and the status goes through the task's interpreter (extended error info,
    warnings) like any wrapped call.
    """
    lib = nidaqmx._lib
    fn = getattr(lib.lib_importer.windll, f"DAQmxSetRealTime{name}")
    if fn.argtypes is None:
        with fn.arg_lock:
            if fn.argtypes is None:
                fn.argtypes = [lib.lib_importer.task_handle, c_type]
    task._interpreter.check_for_error(fn(task._handle, value))


def set_report_missed_samp(nidaqmx: Any, task: Any, enable: bool) -> None:
    """DAQmx_RealTime_ReportMissedSamp: Read raises -209800 / -201027 after missed clocks."""
    _set_real_time(nidaqmx, task, "ReportMissedSamp", nidaqmx._lib.c_bool32, bool(enable))


def set_warmup_iterations(nidaqmx: Any, task: Any, n: int) -> None:
    """DAQmx_RealTime_NumOfWarmupIters (NI's default 100): iterations before lateness is reported."""
    _set_real_time(nidaqmx, task, "NumOfWarmupIters", ctypes.c_uint32, int(n))


def visible_devices(device: str = "Dev1") -> list[str]:
    """Names of the DAQmx devices this machine sees; raises DaqUnavailableError without the NI driver."""
    nidaqmx = _import_nidaqmx(device)
    try:
        return list(nidaqmx.system.System.local().devices.device_names)
    except nidaqmx.errors.DaqNotFoundError as err:
        raise DaqUnavailableError(
            device, (), f"NI-DAQmx driver not found ({err}); cannot open DAQ device {device!r}"
        ) from err
    except nidaqmx.errors.DaqError as err:
        raise DaqUnavailableError(
            device,
            (),
            f"NI-DAQmx cannot list devices (status {err.error_code}); cannot open DAQ device {device!r}",
        ) from err


def _open_failure(errors: Any, dev: str, step: str, err: Exception) -> Exception:
    """The error :meth:`NidaqmxBackend.open` raises for a DAQmx error at ``step``."""
    if isinstance(err, errors.DaqNotFoundError):
        return DaqUnavailableError(
            dev, (), f"NI-DAQmx driver not found ({err}); cannot open DAQ device {dev!r}"
        )
    if isinstance(err, errors.DaqFunctionNotSupportedError):
        return DaqSetupError(
            f"{dev}: {step} failed: {_first_line(err)} (set loop.report_missed_samples: false "
            "to run without it; late cycles then read stale samples unreported)"
        )
    hint = ""
    if (
        err.error_code == -200842
        or "HW_TIMED" in str(err).upper()
        or "single point" in str(err).lower()
    ):
        hint = " (if the device cannot time this channel type in HW-timed single point, set loop.ci_timing / loop.ao_timing: on_demand or loop.timing: software)"
    return DaqSetupError(f"{dev}: {step} failed: DAQmx {err.error_code}: {_first_line(err)}{hint}")


class NidaqmxBackend:
    """The rig: AI ×4 (pressures, laser), CI angular encoder (X4), AO ×2 (valves).

    ``rig.loop.timing == "hardware"``: HW-timed single point at ``rate_hz``, the
    AI read paces the loop (``hardware_paced``); ``"software"``: every task on
    demand, the loop paces itself. Not thread-safe: one loop thread only.
    """

    def __init__(self, rig: RigParams):
        self.rig = rig
        lp = rig.loop
        self.hardware_paced = lp.timing == "hardware"
        self.device_id = rig.device
        self._ci_clocked = self.hardware_paced and lp.ci_timing == "sample_clock"
        self._ao_clocked = self.hardware_paced and lp.ao_timing == "sample_clock"
        self._timeout = lp.read_timeout_s
        self._nidaqmx: Any = None
        self._tasks: list[Any] = []
        self._ai_reader: Any = None
        self._ci_reader: Any = None
        self._writer: Any = None
        self._do_writer: Any = None
        self._ai_buf = np.zeros(len(AI_SENSORS), dtype=np.float64)
        self._ao_buf = np.zeros(2, dtype=np.float64)
        self._counts = 0
        self.is_open = False

    def _phys(self, channel: str) -> str:
        return f"{self.rig.device}/{channel}"

    # -------------------------------------------------------------- lifecycle
    def open(self) -> None:
        """Check the device, write the safe value, create and start the three tasks."""
        rig = self.rig
        dev = rig.device
        nidaqmx = _import_nidaqmx(dev)
        self._nidaqmx = nidaqmx
        names = visible_devices(dev)
        if dev not in names:
            raise DaqUnavailableError(dev, names)
        errors = nidaqmx.errors
        step = "writing the safe value"
        try:
            self._write_safe_on_demand()
            step = "creating the AI task"
            ai = self._open_ai()
            if self.hardware_paced and rig.loop.report_missed_samples:
                step = "enabling missed-sample reporting (DAQmx_RealTime_ReportMissedSamp)"
                set_report_missed_samp(nidaqmx, ai, True)
                # from the first cycle: a late read NI's warm-up let pass would shift
                # every later sample index (and trip the encoder-jump rule)
                set_warmup_iterations(nidaqmx, ai, 0)
            step = "creating the encoder (CI) task"
            ci = self._open_ci()
            step = "creating the valve (AO) task"
            ao = self._open_ao()
            self._open_streams(ai, ci, ao)
            if rig.heartbeat.enabled:
                step = f"creating the heartbeat (DO) task on {rig.heartbeat.line}"
                self._open_heartbeat()
            self._write_first_safe()
            step = "starting the tasks"
            ci.start()
            ao.start()
            ai.start()  # the master clock last
        except (
            errors.DaqNotFoundError,
            errors.DaqFunctionNotSupportedError,
            errors.DaqError,
        ) as err:
            self._abort()
            raise _open_failure(errors, dev, step, err) from err
        self._counts = 0
        self.is_open = True

    def _open_ai(self) -> Any:
        """The AI task (four sensors); HW-timed single point at the loop rate when hardware-paced."""
        rig, c = self.rig, self._nidaqmx.constants
        ai = self._new_task()
        for name in AI_SENSORS:
            ai.ai_channels.add_ai_voltage_chan(
                self._phys(getattr(rig.channels, name)),
                name,
                terminal_config=c.TerminalConfiguration[getattr(rig.ai.terminal, name)],
                min_val=rig.ai.min_v,
                max_val=rig.ai.max_v,
            )
        if self.hardware_paced:
            ai.timing.cfg_samp_clk_timing(
                rig.loop.rate_hz, source="", sample_mode=c.AcquisitionType.HW_TIMED_SINGLE_POINT
            )
        return ai

    def _open_ci(self) -> Any:
        """The encoder task (angular, X1/X2/X4, digital filter); on the AI clock if clocked."""
        rig, c = self.rig, self._nidaqmx.constants
        ci = self._new_task()
        chan = ci.ci_channels.add_ci_ang_encoder_chan(
            self._phys(rig.channels.encoder),
            "encoder",
            decoding_type=c.EncoderType["X_" + rig.encoder.decoding[1:]],
            zidx_enable=False,
            units=c.AngleUnits.TICKS,
            pulses_per_rev=rig.encoder.ppr,
            initial_angle=0.0,
        )
        width = DIG_FILTERS[rig.encoder.dig_filter]
        for phase in ("a", "b"):  # DAQmx coerces the width to a setting the device has
            setattr(chan, f"ci_encoder_{phase}_input_dig_fltr_enable", width > 0.0)
            if width > 0.0:
                setattr(chan, f"ci_encoder_{phase}_input_dig_fltr_min_pulse_width", width)
        if self._ci_clocked:
            chan.ci_data_xfer_mech = (
                c.DataTransferActiveTransferMode.POLLED
            )  # HWTSP counters need programmed I/O
            ci.timing.cfg_samp_clk_timing(
                rig.loop.rate_hz,
                source=f"/{rig.device}/ai/SampleClock",
                sample_mode=c.AcquisitionType.HW_TIMED_SINGLE_POINT,
            )
        return ci

    def _open_ao(self) -> Any:
        """The valve task (two AO channels); on the AI clock if clocked."""
        rig, c = self.rig, self._nidaqmx.constants
        ao = self._new_task()
        for name, channel in (
            ("valve_linear", rig.channels.valve_linear),
            ("valve_rotary", rig.channels.valve_rotary),
        ):
            ao.ao_channels.add_ao_voltage_chan(
                self._phys(channel), name, min_val=rig.ao.min_v, max_val=rig.ao.max_v
            )
        if self._ao_clocked:
            ao.timing.cfg_samp_clk_timing(
                rig.loop.rate_hz,
                source=f"/{rig.device}/ai/SampleClock",
                sample_mode=c.AcquisitionType.HW_TIMED_SINGLE_POINT,
            )
        return ao

    def _open_streams(self, ai: Any, ci: Any, ao: Any) -> None:
        """The stream readers and the writer the loop calls every cycle."""
        nidaqmx = self._nidaqmx
        self._ai_reader = nidaqmx.stream_readers.AnalogMultiChannelReader(ai.in_stream)
        self._ci_reader = nidaqmx.stream_readers.CounterReader(ci.in_stream)
        self._writer = nidaqmx.stream_writers.AnalogMultiChannelWriter(
            ao.out_stream, auto_start=False
        )
        for rw in (self._ai_reader, self._ci_reader, self._writer):
            rw.verify_array_shape = False  # one driver query less per call

    def _open_heartbeat(self) -> None:
        """The heartbeat DO line, on demand, started low."""
        rig, c = self.rig, self._nidaqmx.constants
        do = self._new_task()
        do.do_channels.add_do_chan(
            self._phys(rig.heartbeat.line),
            "heartbeat",
            line_grouping=c.LineGrouping.CHAN_PER_LINE,
        )
        self._do_writer = self._nidaqmx.stream_writers.DigitalSingleChannelWriter(
            do.out_stream, auto_start=False
        )
        self._do_writer.verify_array_shape = False
        do.start()  # on demand: each write sets the line at once
        self._do_writer.write_one_sample_one_line(False, timeout=self._timeout)

    def _write_first_safe(self) -> None:
        """The first value of the timed AO task: safe (the on-demand write already set it)."""
        self._ao_buf[:] = self.rig.ao.safe_v
        try:
            self._writer.write_one_sample(self._ao_buf, timeout=self._timeout)
        except self._nidaqmx.errors.DaqError as err:
            log.warning(
                "%s: pre-start AO write refused (DAQmx %s); the on-demand safe value holds",
                self.rig.device,
                err.error_code,
            )

    def _new_task(self) -> Any:
        task = self._nidaqmx.Task()
        self._tasks.append(task)
        return task

    def _write_safe_on_demand(self) -> None:
        """A throw-away on-demand AO task: both valves to the safe value, immediately."""
        rig = self.rig
        task = self._nidaqmx.Task()
        try:
            for name, channel in (
                ("valve_linear", rig.channels.valve_linear),
                ("valve_rotary", rig.channels.valve_rotary),
            ):
                task.ao_channels.add_ao_voltage_chan(
                    self._phys(channel), name, min_val=rig.ao.min_v, max_val=rig.ao.max_v
                )
            task.write([rig.ao.safe_v, rig.ao.safe_v], auto_start=True, timeout=1.0)
        finally:
            task.close()

    def _abort(self) -> None:
        try:
            self.close()
        except Exception as err:  # the setup error is the one to report
            log.error("while cleaning up after a failed open: %s", err)

    def close(self) -> None:
        """Stop and close every task (AI first: it is the clock), then write the safe value on demand.

        Every step is tried; the first failure is raised afterwards as :class:`DaqIoError`.
        """
        nidaqmx = self._nidaqmx
        if nidaqmx is None:
            return
        errors: list[str] = []
        for task in self._tasks:  # creation order: AI, CI, AO
            try:
                task.stop()
            except nidaqmx.errors.Error as err:
                errors.append(f"stop: {_first_line(err)}")
        for task in self._tasks:
            try:
                task.close()
            except nidaqmx.errors.Error as err:
                errors.append(f"close: {_first_line(err)}")
        self._tasks.clear()
        self._ai_reader = self._ci_reader = self._writer = self._do_writer = None
        was_open, self.is_open = self.is_open, False
        try:
            self._write_safe_on_demand()
        except nidaqmx.errors.Error as err:
            errors.append(f"safe write: {_first_line(err)}")
        if errors and was_open:
            raise DaqIoError(f"{self.rig.device}: closing the DAQ: " + "; ".join(errors))
        for e in errors:
            log.error("%s: closing the DAQ: %s", self.rig.device, e)

    # ------------------------------------------------------------------ cycle
    def read(self) -> RawSample:
        """One sample of the four AI channels and the encoder count (blocks on the clock in HW mode)."""
        errors = self._nidaqmx.errors
        late: list[int] = []
        raw_count = None
        try:
            self._ai_reader.read_one_sample(self._ai_buf, timeout=self._timeout)
        except errors.DaqError as err:
            if err.error_code not in LATE_CODES:
                raise DaqIoError(
                    f"{self.rig.device}: AI read failed: DAQmx {err.error_code}: {_first_line(err)}"
                ) from err
            late.append(err.error_code)
        try:
            raw_count = self._ci_reader.read_one_sample_double(timeout=self._timeout)
        except errors.DaqError as err:
            if err.error_code not in LATE_CODES:
                raise DaqIoError(
                    f"{self.rig.device}: encoder read failed: DAQmx {err.error_code}: {_first_line(err)}"
                ) from err
            late.append(err.error_code)
        if late:
            raise LateCycleError(tuple(late))
        self._counts = unwrap_counts(self._counts, round(raw_count), self.rig.encoder.counter_bits)
        v = self._ai_buf
        return RawSample((float(v[0]), float(v[1]), float(v[2]), float(v[3])), self._counts)

    def heartbeat(self, level: bool) -> None:
        """Set the heartbeat DO line (on demand: at once). No line configured: nothing."""
        if self._do_writer is None:
            return
        try:
            self._do_writer.write_one_sample_one_line(bool(level), timeout=self._timeout)
        except self._nidaqmx.errors.DaqError as err:
            raise DaqIoError(
                f"{self.rig.device}: heartbeat write failed: DAQmx {err.error_code}: {_first_line(err)}"
            ) from err

    def write(self, u_linear: float, u_rotary: float) -> None:
        """Both valve voltages (clamped to the AO range); emitted at the next clock in HW mode."""
        ao = self.rig.ao
        self._ao_buf[0] = ao_volts(u_linear, ao)
        self._ao_buf[1] = ao_volts(u_rotary, ao)
        try:
            self._writer.write_one_sample(self._ao_buf, timeout=self._timeout)
        except self._nidaqmx.errors.DaqError as err:
            if err.error_code in LATE_CODES:
                raise LateCycleError((err.error_code,)) from err
            raise DaqIoError(
                f"{self.rig.device}: AO write failed: DAQmx {err.error_code}: {_first_line(err)}"
            ) from err


def _first_line(err: BaseException) -> str:
    text = str(err).strip()
    return text.splitlines()[0] if text else type(err).__name__
