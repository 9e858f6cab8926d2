"""The rotary safety rules on the twin, both plumbings: angle soft limits, a stalled rotation,
a task that ends safe; the pre-run checks of an angle reference.

Each run is the in-process runner on the nominal twin in ``rotary_control: angle`` with the
controllers a task uses (:func:`pneu_control.task.session.rotary_defaults`: coast with the
paper's plumbing, pva with the bidirectional one). Bounds come from the rules'
definitions applied to the recorded samples and valve voltages, not from stored numbers.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from pneu_control.experiment.runner import run
from pneu_control.experiment.session import build_spec
from pneu_control.task.session import rotary_defaults
from pneu_driver.safety import SafetyParams
from pneu_msgs_py.params.core import ParamError, with_updates
from pneu_sim.physics.plant_file import load_plant

PLUMBINGS = ("paper", "bidirectional")
T = 1e-3  # the twin's sample period (config/plant.yaml sim.T)


def angle_spec(plumbing, reference, duration_s, loads=None, **safety):
    """A rotary angle run; ``reference``: the reference.* fields (degrees)."""
    sets = ["rotary_control=angle", *(f"reference.{k}={v}" for k, v in reference.items())]
    defaults = rotary_defaults(plumbing)  # what a task runs with this plumbing
    alg = defaults["algorithm"]
    sets += [f"{k}={v}" for k, v in defaults.items() if k not in ("algorithm", "rotary_control")]
    updates = {"rotary.plumbing": plumbing, **{f"load.{k}": v for k, v in (loads or {}).items()}}
    plant = with_updates(load_plant(), updates)
    sp = SafetyParams(rotary_plumbing=plumbing)
    spec = build_spec(
        axes=("rotary",), controller=alg, sets=sets, duration_s=duration_s, plant=plant, safety=sp
    )
    # a reference beyond the soft limits is refused by build_spec (checks.py): the limits are
    # set after the checks, to make the supervisor act
    return dataclasses.replace(spec, safety=dataclasses.replace(sp, **safety))


def errors(result):
    return [(e.axis, e.rule) for e in result.safety_events if e.level == "ERROR"]


def driven(result, p):
    """Per sample k: the stall rule's "driven" (the valve of tick k-1 beyond the band toward a
    driving port, forward with the inlet above stall_inlet_pa)."""
    both = p.rotary_plumbing == "bidirectional"
    band = p.stall_band_bidir_v if both else p.stall_band_v
    u = np.r_[5.0, result.applied["rotary"][:-1]]  # sample k sees the output of tick k-1
    fwd = (u - 5.0 > band) & (result.samples["p_m1"] > p.stall_inlet_pa)
    rev = (5.0 - u > band) & both
    return fwd | rev


# ------------------------------------------------------------------ angle soft limits
LIMITS = dict(angle_limits=True, angle_min_deg=-100.0, angle_max_deg=100.0, angle_margin_deg=10.0)


@pytest.mark.parametrize("plumbing", PLUMBINGS)
def test_a_move_toward_an_angle_soft_limit_stops_safe_at_it(plumbing):
    """A ramp at 30 rpm toward +90° (the soft limit of a tool tolerating ±100°) and on: the
    hold and, past the limit, the latched trip stop the motor inside the tool's range, at
    the limit; the valve ends where it does not turn the motor (paper: the inlet vented,
    as 5 V's centre leakage turns it on; bidirectional: 5 V)."""
    ramp = {"kind": "ramp", "offset": 0.0, "slope": 180.0}  # °/s
    result = run(angle_spec(plumbing, ramp, 1.6, **LIMITS))
    theta = np.degrees(result.samples["theta"])
    assert theta.max() < LIMITS["angle_max_deg"]  # the tool's limit never reached
    rest = theta[-200:]
    assert np.all(rest == rest[-1]), "still turning"
    assert 90.0 - LIMITS["angle_margin_deg"] <= rest[-1] < LIMITS["angle_max_deg"]
    held = [e for e in result.safety_events if e.rule == "soft_limit" and e.level == "WARN"]
    assert held and held[0].axis == "rotary"
    idle = 0.0 if plumbing == "paper" else 5.0
    assert result.applied["rotary"][-1] <= idle
    # past the soft limit, no output turning the motor further was written
    k_over = np.flatnonzero(theta >= 90.0)
    if len(k_over):
        assert np.all(result.applied["rotary"][k_over[0] :] <= idle)


# ------------------------------------------------------------------ stalled rotation
@pytest.mark.parametrize(
    ("plumbing", "target"),
    [("paper", 90.0), ("bidirectional", 90.0), ("bidirectional", -90.0)],
    ids=["paper-forward", "bidirectional-forward", "bidirectional-reverse"],
)
def test_a_blocked_rotation_trips_the_stall_rule_within_its_time(plumbing, target):
    """A load that never breaks away (T_bk = 10 N·m, ≫ the motor's ≈ 0.75 N·m at supply):
    the motor never turns, the rule trips stall_ms after the valve started driving it (the
    first sample strictly beyond), and the valve stays safe from then on."""
    step = {"kind": "smooth_step", "offset": 0.0, "target": target, "duration_s": 0.25}
    spec = angle_spec(plumbing, step, 0.6, loads={"T_bk": 10.0})
    result = run(spec)
    p = spec.safety
    assert np.all(result.samples["counts"] == 0)
    assert errors(result) == [("rotary", "no_rotation")]
    [ev] = [e for e in result.safety_events if e.level == "ERROR"]
    k_trip = round(ev.stamp_ns * 1e-9 / T)
    d = driven(result, p)
    assert d[k_trip]
    k0 = k_trip + 1 - int(np.argmin(d[k_trip::-1]))  # the driven spell's first sample
    # the clock ran from k0 (the motor never turned): the first sample strictly beyond stall_ms
    assert (k_trip - k0) * T == pytest.approx(p.stall_ms * 1e-3 + T)
    direction = "forward" if target > 0 else "in reverse"
    assert f"driven {direction}" in ev.message
    assert np.all(result.applied["rotary"][k_trip:] == 5.0)


@pytest.mark.parametrize("plumbing", PLUMBINGS)
def test_a_90_degree_move_and_a_hold_do_not_trip(plumbing):
    """The move, then a second of holding the angle (the valve near the centre, the chambers
    trapped): no rule trips; the stall clock never ran for stall_ms."""
    if plumbing == "paper":
        ref = {"kind": "constant", "value": 90.0}  # coast: one-way, from rest
    else:
        ref = {"kind": "smooth_step", "offset": 0.0, "target": 90.0, "duration_s": 0.25}
    spec = angle_spec(plumbing, ref, 1.5)
    result = run(spec)
    assert errors(result) == []
    theta = np.degrees(result.samples["theta"])
    assert abs(theta[-1] - 90.0) < 5.0  # it did move there
    assert longest_driven_and_still(result, spec.safety) * T < spec.safety.stall_ms * 1e-3


@pytest.mark.parametrize("plumbing", PLUMBINGS)
def test_a_load_that_breaks_away_within_the_time_does_not_trip(plumbing):
    """T_bk = 0.1 N·m (the motor needs ≈ 1.2 bar gauge more to start): it breaks away."""
    ref = {"kind": "smooth_step", "offset": 0.0, "target": 90.0, "duration_s": 0.25}
    if plumbing == "paper":
        ref = {"kind": "constant", "value": 90.0}
    result = run(angle_spec(plumbing, ref, 0.8, loads={"T_bk": 0.1}))
    assert ("rotary", "no_rotation") not in errors(result)
    assert np.degrees(result.samples["theta"]).max() > 45.0


def longest_driven_and_still(result, p):
    """Longest run of samples driven with |speed| over the speed window below the threshold."""
    c = result.samples["counts"].astype(np.int64)
    n = round(p.speed_window_ms * 1e-3 / T)
    rpm = np.zeros(len(c))
    rpm[n:] = (c[n:] - c[:-n]) * 60.0 / (p.counts_per_rev * n * T)
    slow = np.abs(rpm) < p.stall_speed_rpm
    best = cur = 0
    for flag in driven(result, p) & slow:
        cur = cur + 1 if flag else 0
        best = max(best, cur)
    return best


# ------------------------------------------------------------------ a vented inlet is no stuck sensor
def longest_constant(v):
    """Longest run of bit-identical consecutive values of ``v``."""
    best = cur = 1
    for a, b in itertools.pairwise(v):
        cur = cur + 1 if a == b else 1
        best = max(best, cur)
    return best


def test_a_vented_inlet_is_no_stuck_sensor_and_a_stuck_one_still_trips():
    """Paper plumbing, coast to 90° and a second held vented (0 V): on plants whose p_m1
    sensor offset is below zero the vented reading clips at the sensor's 0 V for far longer
    than stuck_ms, bit-identical (the test checks it did); no rule trips. The same move with
    the p_m1 sensor frozen while the motor is driven (a real stuck sensor) trips stuck."""
    p = SafetyParams()
    clipped = 0
    for seed in range(6):
        spec = dataclasses.replace(angle_spec("paper", {"kind": "constant", "value": 90.0}, 1.5),
                                   seed=seed)  # fmt: skip
        result = run(spec)
        p_m1 = result.samples["p_m1"]
        if longest_constant(p_m1) * T > 2 * p.stuck_ms * 1e-3:
            clipped += 1
            assert p_m1[-1] == spec.plant.ambient.p_a  # the sensor's zero: atmosphere, clipped
        assert errors(result) == [], seed
    assert clipped >= 2  # the exemption was exercised (6 seeds: offsets drawn in ±0.5 % FS)
    spec = angle_spec("paper", {"kind": "constant", "value": 90.0}, 1.0)
    driving = run(spec)
    k = int(np.argmax(driving.samples["p_m1"]))  # the inlet at its highest: driven
    fault = f"stuck_sensor:sensor=p_m1,start_s={k * T:.3f},duration_s=0.5"
    result = run(build_spec(
        axes=("rotary",), controller="coast", sets=["rotary_control=angle",
        "reference.kind=constant", "reference.value=90.0"], duration_s=1.0, plant=spec.plant,
        safety=spec.safety, faults=[fault],
    ))  # fmt: skip
    assert ("rotary", "stuck") in errors(result)


# ------------------------------------------------------------------ a task ends safe
def test_a_blocked_task_segment_aborts_with_both_valves_safe(tmp_path):
    """A rotate segment against a load that never breaks away: the stall rule trips, the task
    aborts (e-stop) and both valves sit at 5 V to the end of the run."""
    from pneu_control.task.runner import TaskDriver
    from pneu_control.task.session import prepare

    task = tmp_path / "blocked.yaml"
    task.write_text(
        "name: blocked\nplumbing: bidirectional\nsegments:\n"
        "  - move: {to_mm: 10.0, speed_mm_s: 50.0}\n    timeout_s: 2.0\n"
        "  - rotate: {by_deg: 90.0, speed_rpm: 60.0}\n    load: {T_bk: 10.0}\n"
        "    timeout_s: 2.0\n"
    )
    prepared = prepare(task)
    assert prepared.spec.safety.rotary_plumbing == "bidirectional"  # the twin's, for the rule
    p = prepared.spec.plant
    driver = TaskDriver(prepared.program, A_c1=p.linear.A_c1, A_c2=p.linear.A_c2, p_a=p.ambient.p_a)
    result = run(prepared.spec, hook=driver)
    assert driver.outcome == "aborted" and "safety" in driver.reason
    assert errors(result)[0] == ("rotary", "no_rotation")
    [estop] = [e for e in result.safety_events if e.rule == "estop"]
    k = round(estop.stamp_ns * 1e-9 / T)
    for axis in ("linear", "rotary"):
        assert np.all(result.applied[axis][k + 1 :] == 5.0), axis
    assert len(result.t) - k > 100  # the safe tail is in the recording


# ------------------------------------------------------------------ pre-run checks
def test_angle_references_are_checked_against_the_angle_limits_and_the_overspeed():
    def spec(ref, safety=True):
        sets = ["rotary.rotary_control=angle", *(f"rotary.reference.{k}={v}" for k, v in ref)]
        return build_spec(
            axes=("rotary",), controller="ladrc", sets=sets, duration_s=0.5, safety=safety
        )

    spec([("kind", "constant"), ("value", 3600.0)])  # ten turns: an angle, not a speed
    limited = dataclasses.replace(SafetyParams(), **LIMITS)
    spec([("kind", "constant"), ("value", 90.0)], limited)
    with pytest.raises(
        ParamError,
        match=r"^rotary.reference: 'constant:value=91' refused; allowed: an angle reference "
        r"inside the angle soft limits \[-90, 90\]°",
    ):
        spec([("kind", "constant"), ("value", 91.0)], limited)
    with pytest.raises(ParamError, match=r"turning within ±1500 rpm .*turns at 1500\.2 rpm"):
        spec([("kind", "ramp"), ("slope", 9001.0)])  # °/s
    with pytest.raises(ParamError, match=r"^rotary_plumbing: 'bidirectional' refused"):
        spec([("kind", "constant"), ("value", 0.0)], SafetyParams(rotary_plumbing="bidirectional"))
