"""The 1 kHz driver loop core: read → publish → newest command → supervisor → write.

One cycle (DESIGN §3, k = tick, T = 1 ms):

1. read sample k (hardware pacing: the HW-timed single-point read blocks until
   clock k; software pacing: sleep + spin to the absolute deadline t0 + k·T);
2. the supervisor checks it, ``on_sample(sample)`` publishes it;
3. wait (at most ``command_deadline_us`` after the tick) for the expected
   controllers' commands answering sample k, take the newest of each axis;
4. the supervisor turns them into the voltages for tick k+1 (an axis without a
   fresh command: its ``late_policy``, DESIGN §14), which are written:
   hardware AO on the sample clock emits them at clock k+1; software pacing
   holds them and writes them at the deadline of tick k+1, just before reading
   sample k+1 -- a one-sample transport delay either way.

5. the heartbeat DO line toggles (``heartbeat.enabled``), unless the
   supervisor has tripped (``heartbeat.stop_on_trip``): an external
   missing-pulse relay keeps the supply air on only while it sees edges.

Deadlines are absolute (t0 + k·T), so errors never accumulate; a cycle that
starts more than a whole period late skips the missed ticks (counted). DAQmx
late errors (:data:`~pneu_driver.daq.nidaqmx_backend.LATE_CODES`) are counted
as late cycles (per code in ``late_codes``) and the loop goes on;
``max_consecutive_late`` in a row stop it. Whatever ends the loop (``stop()``,
``n_cycles``, an exception), ``finally`` writes the safe value, leaves the
heartbeat low (no more edges) and closes the backend.

``LoopStats`` also keeps each cycle's cost: from the sample's arrival (the
read's return; software pacing: the cycle's start) to the end of its write and
heartbeat -- the work the loop does per period, waiting for commands included.

Threads: ``run`` owns the backend and the loop; ``put_command``, ``stop``,
``estop``, ``reset``, ``acknowledge`` and ``status`` may be called from any
thread. Callbacks run in the loop thread and must be quick.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable

from pneu_msgs_py.contract.samples import AXES, SensorSample
from pneu_msgs_py.lifecycle.realtime import enable_realtime

from pneu_driver.daq.backend import DaqBackend
from pneu_driver.daq.claim import device_claim
from pneu_driver.daq.errors import DriverError, LateCycleError
from pneu_driver.daq.rig import RigParams
from pneu_driver.daq.scaling import RawSample, Scaler
from pneu_driver.loop.stats import LoopStats
from pneu_driver.safety import SAFE_V, AxisStatus, SafetyEvent, SafetySupervisor, check_plumbing

__all__ = ["CommandSlot", "LoopStats", "DriverLoop"]

log = logging.getLogger("pneu_driver.loop.driver_loop")


class CommandSlot:
    """The newest command per axis, set from any thread, taken by the loop thread.

    A command with an older stamp than one already seen for its axis is dropped, and so
    is one stamped after the newest sample taken (:meth:`taken`): it answers no sample,
    and were it kept, its stamp would make every true answer look older (counted in
    ``future``, per axis).
    """

    def __init__(self, axes: Iterable[str] = AXES):
        self._cond = threading.Condition(threading.Lock())
        self._newest = dict.fromkeys(axes, -(1 << 62))
        self._pending: dict[str, tuple[float, int]] = {}
        self._sample_ns = -(1 << 62)  # no sample taken yet: every command is early
        self.future = dict.fromkeys(axes, 0)

    def taken(self, stamp_ns: int) -> None:
        """Sample ``stamp_ns`` was taken: commands may answer it (loop thread)."""
        with self._cond:
            self._sample_ns = stamp_ns

    def put(self, axis: str, u: float, stamp_ns: int) -> bool:
        """Store ``u`` [V] for ``axis`` (answering the sample stamped ``stamp_ns``); False if older."""
        with self._cond:
            if axis not in self._newest:
                raise ValueError(
                    f"axis: {axis!r} refused; allowed: one of {', '.join(self._newest)}"
                )
            if stamp_ns > self._sample_ns:
                self.future[axis] += 1
                return False
            if stamp_ns < self._newest[axis]:
                return False
            self._newest[axis] = stamp_ns
            self._pending[axis] = (u, stamp_ns)
            self._cond.notify_all()
        return True

    def wait_fresh(self, axes: tuple[str, ...], stamp_ns: int, timeout_s: float) -> bool:
        """Block until every axis in ``axes`` has a command stamped ≥ ``stamp_ns`` (or the timeout)."""
        newest = self._newest
        with self._cond:
            return self._cond.wait_for(
                lambda: all(newest[a] >= stamp_ns for a in axes), max(timeout_s, 0.0)
            )

    def take(self) -> list[tuple[str, float, int]]:
        """The commands that arrived since the last take: (axis, u, stamp_ns)."""
        with self._cond:
            if not self._pending:
                return []
            out = [(a, u, s) for a, (u, s) in self._pending.items()]
            self._pending.clear()
        return out


class DriverLoop:
    """The driver's loop core around a :class:`~pneu_driver.daq.backend.DaqBackend`.

    Parameters
    ----------
    backend
        The DAQ (``NidaqmxBackend``) or a plant behind ``SimBackend``.
    rig
        Loop rate, pacing, command deadline, tolerances, AO safe value.
    supervisor
        Its sample time must be the loop period, its ``counts_per_rev`` and
        ``rotary_plumbing`` the rig's.
    on_sample
        Called with each :class:`SensorSample` (publish it).
    on_events
        Called with the supervisor's transitions (publish on ``/diagnostics``).
    expected_axes
        Axes whose controller's command for sample k the loop waits for
        (at most ``command_deadline_us``); the others are not waited for.
    epoch_ns
        Stamp of tick 0: ``stamp_ns = epoch_ns + k·T``.
    clock_ns, sleep
        Injectable clock (monotonic int ns) and sleep [s] for tests.
    """

    def __init__(
        self,
        backend: DaqBackend,
        rig: RigParams,
        supervisor: SafetySupervisor,
        *,
        on_sample: Callable[[SensorSample], None] | None = None,
        on_events: Callable[[list[SafetyEvent]], None] | None = None,
        expected_axes: Iterable[str] = AXES,
        epoch_ns: int = 0,
        clock_ns: Callable[[], int] = time.perf_counter_ns,
        sleep: Callable[[float], None] = time.sleep,
    ):
        if rig.loop.timing == "hardware" and not backend.hardware_paced:
            raise ValueError(
                "loop.timing: 'hardware' refused for a backend that does not block on a sample clock; allowed: software"
            )
        if abs(supervisor.sample_time_s - rig.period_s) > 1e-12:
            raise ValueError(
                f"supervisor sample_time_s {supervisor.sample_time_s!r} refused; allowed: the loop period {rig.period_s!r} s"
            )
        if supervisor.params.counts_per_rev != rig.encoder.counts_per_rev:
            raise ValueError(
                f"safety counts_per_rev: {supervisor.params.counts_per_rev} refused; allowed: the rig's encoder counts per revolution {rig.encoder.counts_per_rev}"
            )
        check_plumbing(supervisor.params, rig.rotary_plumbing, "the rig's rotary_plumbing")
        if rig.encoder.max_filtered_rpm < supervisor.params.max_speed_rpm:
            raise ValueError(
                f"encoder.dig_filter: {rig.encoder.dig_filter!r} refused; allowed: a filter passing "
                f"the overspeed trip {supervisor.params.max_speed_rpm:g} rpm (this one loses counts above "
                f"{rig.encoder.max_filtered_rpm:.0f} rpm at {rig.encoder.ppr} P/R)"
            )
        if rig.ao.safe_v != SAFE_V:
            raise ValueError(
                f"ao.safe_v: {rig.ao.safe_v} refused; allowed: {SAFE_V} V (the supervisor's safe value)"
            )
        self.expected_axes = tuple(expected_axes)
        for a in self.expected_axes:
            if a not in AXES:
                raise ValueError(f"expected_axes: {a!r} refused; allowed: {', '.join(AXES)}")
        self.backend = backend
        self.rig = rig
        self.hardware_paced = bool(backend.hardware_paced)
        self._sup = supervisor
        self._on_sample = on_sample
        self._on_events = on_events
        self._epoch_ns = int(epoch_ns)
        self._clock = clock_ns
        self._sleep = sleep
        self._T = rig.period_ns
        self._cmd_deadline_ns = round(rig.loop.command_deadline_us * 1e3)
        self._spin_ns = round(rig.loop.spin_us * 1e3)
        self._scaler = Scaler(rig)
        self._lock = threading.Lock()  # guards the supervisor
        self._stop = threading.Event()
        self.commands = CommandSlot(AXES)
        self.stats = LoopStats(rig.loop.stats_window, round(rig.loop.on_time_tol_us * 1e3))
        self.error: BaseException | None = None
        self.last_sample: SensorSample | None = None
        self.realtime_notes: list[str] = []
        hb = rig.heartbeat
        self._hb_on = hb.enabled
        self._hb_stop_on_trip = hb.stop_on_trip
        self._hb_level = False
        self._tripped = False  # the supervisor's latch, read under the lock once per cycle

    # ------------------------------------------------------------ any thread
    def put_command(self, axis: str, u: float, stamp_ns: int) -> bool:
        """A controller's valve command (V) answering the sample stamped ``stamp_ns``."""
        return self.commands.put(axis, u, stamp_ns)

    def stop(self) -> None:
        """Ask the loop to finish its cycle, write the safe value and close."""
        self._stop.set()

    def estop(self, reason: str) -> None:
        with self._lock:
            self._sup.estop(reason)

    def reset(self) -> tuple[bool, str]:
        with self._lock:
            return self._sup.reset()

    def acknowledge(self, axis: str) -> tuple[bool, str]:
        with self._lock:
            return self._sup.acknowledge(axis)

    def status(self) -> dict[str, AxisStatus]:
        with self._lock:
            return self._sup.status

    def command_publishers(self, counts: dict[str, int]) -> None:
        """The graph's publisher count per command topic (see ``SafetySupervisor.command_publishers``)."""
        with self._lock:
            self._sup.command_publishers(counts)
            events = self._sup.events()
        if events and self._on_events is not None:
            self._on_events(events)

    def command_counts(self) -> dict[str, str]:
        """The supervisor's counters (commands not taken, trips, per axis the late ticks and
        those held or ramped) and the commands stamped for no sample."""
        with self._lock:
            out = {k: str(v) for k, v in self._sup.counters.items()}
        for axis, n in self.commands.future.items():
            out[f"{axis}.future_commands"] = str(n)
        return out

    def diagnostics(self) -> dict[str, str]:
        """Key-values for the driver's periodic ``/diagnostics`` status (loop timing and axis states)."""
        out = {
            k: f"{v:.6g}" if isinstance(v, float) else str(v)
            for k, v in self.stats.as_dict().items()
        }
        out.update(self.command_counts())
        out["pacing"] = "hardware" if self.hardware_paced else "software"
        out["realtime"] = "; ".join(self.realtime_notes) or "normal scheduling"
        for axis, st in self.status().items():
            out[f"{axis}.state"] = st.state
            out[f"{axis}.causes"] = ",".join(st.causes)
        return out

    def start(
        self, n_cycles: int | None = None, name: str = "pneu_driver_loop"
    ) -> threading.Thread:
        """Run in a new thread; an exception ends up in ``self.error`` (the valves are safe)."""

        def target() -> None:
            try:
                self.run(n_cycles)
            except BaseException as err:  # reported through self.error
                self.error = err
                log.error("driver loop stopped: %s", err)

        th = threading.Thread(target=target, name=name, daemon=True)
        th.start()
        return th

    # ------------------------------------------------------------ loop thread
    def run(
        self, n_cycles: int | None = None, stop_event: threading.Event | None = None
    ) -> LoopStats:
        """Open the backend and run ``n_cycles`` (None: until :meth:`stop` or ``stop_event``)."""
        if n_cycles is not None and n_cycles < 0:
            raise ValueError(f"n_cycles: {n_cycles!r} refused; allowed: an integer ≥ 0 or None")
        stop = stop_event or self._stop  # a stop() before run() ends it at once
        lp = self.rig.loop
        notes, restore_rt = enable_realtime(
            lp.rt_priority, lp.timerslack_ns, lp.switch_interval_us * 1e-6
        )
        self.realtime_notes = notes
        try:
            with device_claim(getattr(self.backend, "device_id", None)):  # one driver per card
                self.backend.open()  # leaves the valves safe; cleans up after itself on failure
                try:
                    if self.hardware_paced:
                        self._run_hardware(n_cycles, stop)
                    else:
                        self._run_software(n_cycles, stop)
                except BaseException:
                    # the error that ended the loop is the one to see
                    self._shutdown(raise_errors=False)
                    raise
                self._shutdown(raise_errors=True)
        finally:
            restore_rt()
        return self.stats

    def _stopped(self, stop: threading.Event) -> bool:
        return stop.is_set() or self._stop.is_set()

    def _run_software(self, n_cycles: int | None, stop: threading.Event) -> None:
        T, clock, stats, backend = self._T, self._clock, self.stats, self.backend
        pending = (SAFE_V, SAFE_V)
        t0 = clock() + T  # deadline of tick 0
        k = 0
        cycles = 0
        while not self._stopped(stop) and (n_cycles is None or cycles < n_cycles):
            deadline = t0 + k * T
            self._wait_until(deadline)
            late = clock() - deadline
            if late >= T:  # whole ticks missed: skip to the current one
                skip = late // T
                k += skip
                deadline += skip * T
                late -= skip * T
                stats.missed_ticks += skip
            stats.record(late)
            start = deadline + late
            backend.write(*pending)  # the command computed from sample k-1, at tick k
            raw = backend.read()
            pending = self._cycle(k, raw, deadline)
            self._beat()
            stats.record_cost(clock() - start)
            k += 1
            cycles += 1

    def _run_hardware(self, n_cycles: int | None, stop: threading.Event) -> None:
        T, clock, stats, backend = self._T, self._clock, self.stats, self.backend
        max_late = self.rig.loop.max_consecutive_late
        k = -1
        t_prev: int | None = None
        # the sample clock's phase on our clock: min over clock-paced reads of (return - k·T)
        # (a read never returns before its clock); may rise by 100 ppm of T per cycle (drift)
        anchor: int | None = None
        drift = T // 10_000
        consecutive = 0
        cycles = 0
        while not self._stopped(stop) and (n_cycles is None or cycles < n_cycles):
            raw: RawSample | None
            at_least = 0  # clocks DAQmx says were missed
            try:
                raw = backend.read()  # blocks until the next sample clock
            except LateCycleError as err:
                raw = None
                at_least = err.min_missed
                stats.daq_late(err.codes)
                consecutive += 1
                if consecutive >= max_late:
                    raise DriverError(
                        f"{consecutive} late cycles in a row (last: {err}); stopping with the valves safe"
                    ) from err
            now = clock()
            step = 1
            if raw is None and t_prev is not None:
                # missed clock(s): a late read returns the newest sample at once, so its clock
                # is the last one before now on the clock's phase; at least what DAQmx says
                est = round((now - t_prev) / T) if anchor is None else (now - anchor) // T - k
                step = max(1 + at_least, est)
            stats.record(0 if t_prev is None else now - t_prev - step * T, late=raw is None)
            stats.missed_ticks += step - 1
            k += step
            t_prev = now
            if raw is not None:
                a = now - k * T
                anchor = a if anchor is None or a < anchor + drift else anchor + drift
            if raw is None:
                stamp = self._epoch_ns + k * T
                with self._lock:
                    out = self._sup.outputs(stamp + T)  # the watchdog still runs
                    events = self._sup.events()
                    self._tripped = self._sup.tripped
                if events and self._on_events is not None:
                    self._on_events(events)
            else:
                consecutive = 0
                out = self._cycle(k, raw, now)
            try:
                backend.write(*out)  # HW AO: emitted at clock k+1
            except LateCycleError as err:
                stats.daq_late(err.codes)
                stats.mark_late()
            self._beat()
            stats.record_cost(clock() - now)
            cycles += 1

    def _cycle(self, k: int, raw: RawSample, tick_ns: int) -> tuple[float, float]:
        """Sample k → supervisor → publish → commands → outputs for tick k+1."""
        T = self._T
        stamp = self._epoch_ns + k * T
        sample = self._scaler.sample(k, stamp, raw)
        self.last_sample = sample
        sup = self._sup
        with self._lock:
            sup.check_sample(sample, raw.volts)
        self.commands.taken(stamp)
        if self._on_sample is not None:
            self._on_sample(sample)
        if self.expected_axes:
            remaining = tick_ns + self._cmd_deadline_ns - self._clock()
            self.commands.wait_fresh(self.expected_axes, stamp, remaining * 1e-9)
        cmds = self.commands.take()
        with self._lock:
            for axis, u, st in cmds:
                sup.command(axis, u, st)
            out = sup.outputs(stamp + T)
            events = sup.events()
            self._tripped = sup.tripped
        if events and self._on_events is not None:
            self._on_events(events)
        return out

    def _beat(self) -> None:
        """Toggle the heartbeat line: this cycle's outputs are written (not while tripped)."""
        if not self._hb_on or (self._hb_stop_on_trip and self._tripped):
            return
        self._hb_level = not self._hb_level
        self.backend.heartbeat(self._hb_level)
        self.stats.heartbeats += 1

    def _wait_until(self, deadline: int) -> None:
        """Sleep until ``spin_us`` before the deadline, then spin on the clock."""
        clock = self._clock
        remaining = deadline - clock()
        if remaining > self._spin_ns:
            self._sleep((remaining - self._spin_ns) * 1e-9)
        while clock() < deadline:
            pass

    def _shutdown(self, raise_errors: bool) -> None:
        """Safe value, heartbeat low (no more edges), then close (the backend writes 5 V once more)."""
        try:
            self.backend.write(SAFE_V, SAFE_V)
        except LateCycleError:
            pass  # written, one clock late; close() writes it once more on demand
        except Exception as err:
            log.error("writing the safe value at shutdown failed: %s", err)
        if self._hb_on:
            try:
                self._hb_level = False
                self.backend.heartbeat(False)
            except Exception as err:
                log.error("setting the heartbeat line low at shutdown failed: %s", err)
        try:
            self.backend.close()
        except Exception as err:
            if raise_errors:
                raise
            log.error("closing the backend after an error failed: %s", err)
