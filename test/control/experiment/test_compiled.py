"""The compiled closed loop (run_compiled) against the Python runner, bit for bit.

Every array of the RunResult (np.array_equal, NaN = NaN), the metrics, the safety
events and counters, for every controller and both gain files, each axis alone and
both together, supervisor on and off, every reference kind, the options of the
algorithms, and supervisor settings that make each mirrored rule act. Short runs.
"""

from __future__ import annotations

import dataclasses
from dataclasses import replace

import numpy as np
import pytest
from pneu_control.controller.params import ANGLE_ONLY_ALGORITHMS, AXIS_ALGORITHMS
from pneu_control.experiment import compiled as compiled_mod
from pneu_control.experiment.compiled import (
    CompiledLoopMismatch,
    compiled_support,
    run_compiled,
    warm_up,
)
from pneu_control.experiment.runner import run
from pneu_control.experiment.session import build_spec
from pneu_driver.safety import SafetyParams
from pneu_msgs_py.params.paths import config_file

PAPER = config_file("controllers.yaml")
RETUNED = config_file("controllers_retuned.yaml")


@pytest.fixture(scope="module", autouse=True)
def _jit():
    warm_up()  # compile (or load from numba's cache) once for the module


def assert_same(a, b):
    """Every recorded array, metric, event and counter of two RunResults is equal."""
    assert np.array_equal(a.t, b.t)
    assert a.samples.keys() == b.samples.keys()
    for k in a.samples:
        assert np.array_equal(a.samples[k], b.samples[k], equal_nan=True), k
    assert a.axes.keys() == b.axes.keys()
    assert list(a.axes) == list(b.axes)
    for axis in a.axes:
        assert a.axes[axis].keys() == b.axes[axis].keys()
        for k in a.axes[axis]:
            assert np.array_equal(a.axes[axis][k], b.axes[axis][k], equal_nan=True), (axis, k)
    for k in ("linear", "rotary"):
        assert np.array_equal(a.applied[k], b.applied[k]), k
    assert a.truth.keys() == b.truth.keys()
    assert a.algorithms == b.algorithms
    assert a.metrics_dict() == b.metrics_dict()
    assert a.safety_events == b.safety_events
    assert a.safety_counters == b.safety_counters
    assert a.fault_intervals == b.fault_intervals
    assert a.interrupted == b.interrupted


def both(spec):
    """(runner, compiled) for ``spec``; the compiled path must not fall back."""
    assert compiled_support(spec) is None
    return run(spec), run_compiled(spec, fallback=False)


def spec_of(axes=("linear", "rotary"), controller=None, sets=(), file=RETUNED, **kw):
    kw.setdefault("duration_s", 0.8)
    return build_spec(
        axes=axes, controller=controller, sets=list(sets), controllers_file=file, **kw
    )


# ------------------------------------------------------------------ controllers × gains
@pytest.mark.parametrize("file", [PAPER, RETUNED], ids=["paper", "retuned"])
@pytest.mark.parametrize("controller", AXIS_ALGORITHMS)
def test_every_controller_both_axes_supervisor_on(controller, file):
    a, b = both(spec_of(controller=controller, file=file, seed=2))
    assert_same(a, b)
    if file == PAPER and controller != "eso_smc_plus":
        # the paper's rotary gains overspeed on the twin: the supervisor trips and latches
        assert any(e.rule == "overspeed" and e.level == "ERROR" for e in a.safety_events)
        assert a.safety_counters["trips"] >= 1
        assert np.all(b.applied["rotary"][-100:] == 5.0)


@pytest.mark.parametrize("controller", AXIS_ALGORITHMS)
def test_every_controller_supervisor_off(controller):
    a, b = both(spec_of(controller=controller, safety=False, seed=5))
    assert_same(a, b)
    assert b.safety_events == [] and b.safety_counters == {}


@pytest.mark.parametrize(
    ("axis", "controller", "file"),
    [
        ("linear", "pid", PAPER),
        ("linear", "eso_smc", PAPER),  # limit cycle into the soft limits
        ("linear", "eso_smc_plus", RETUNED),
        ("rotary", "ladrc", RETUNED),
        ("rotary", "eso_smc", PAPER),
        ("rotary", "eso_smc_plus", PAPER),
    ],
)
def test_one_axis_alone(axis, controller, file):
    a, b = both(spec_of(axes=(axis,), controller=controller, file=file, duration_s=1.2))
    assert_same(a, b)
    other = "rotary" if axis == "linear" else "linear"
    assert np.all(b.applied[other] == 5.0) and other not in b.axes


def test_paper_eso_smc_reaches_the_soft_limits():
    a, b = both(spec_of(axes=("linear",), controller="eso_smc", file=PAPER, duration_s=1.0))
    assert_same(a, b)
    assert any(e.rule == "soft_limit" for e in b.safety_events)


# ------------------------------------------------------------------ references
@pytest.fixture(scope="module")
def waypoint_file(tmp_path_factory):
    f = tmp_path_factory.mktemp("wp") / "w.csv"
    f.write_text("t,value\n0.0,0.0\n0.2,5.0\n0.35,-3.0\n0.6,8.0\n0.7,8.0\n")
    return str(f)


@pytest.mark.parametrize(
    "ref",
    [
        "smooth_step:offset=-5,target=20,duration_s=0.5,t0_s=0.1",
        "ramp:offset=2,slope=30,duration_s=0.4,t0_s=0.05",
        "ramp:offset=0,slope=-10,duration_s=0",
        "constant:value=7",
        "sine:amplitude=10,frequency_hz=2,offset=3,t0_s=0.2",
        "waypoints",
    ],
)
@pytest.mark.parametrize("controller", ["pid", "eso_smc", "eso_smc_plus"])
def test_every_reference_kind(ref, controller, waypoint_file):
    if ref == "waypoints":
        ref = f"waypoints:file={waypoint_file}"
    a, b = both(spec_of(axes=("linear",), controller=controller, reference=ref, seed=1))
    assert_same(a, b)


@pytest.mark.parametrize(
    "ref",
    [
        "smooth_step:offset=0,target=600,duration_s=0.4",
        "ramp:offset=100,slope=1000,duration_s=0.3",
        "sine:amplitude=200,frequency_hz=3,offset=500",
    ],
)
def test_rotary_references(ref):
    a, b = both(spec_of(axes=("rotary",), controller="eso_smc", reference=ref))
    assert_same(a, b)


# ------------------------------------------------------------------ algorithm options
@pytest.mark.parametrize(
    ("controller", "sets"),
    [
        ("pid", ["pid.derivative_on=measurement", "pid.anti_windup=back_calculation"]),
        ("pid", ["pid.anti_windup=none", "linear.pid.y_filter_tf=0.003"]),
        ("ladrc", ["ladrc.accel_feedforward=true", "ladrc.delay_compensation=true"]),
        ("ladrc", ["td.enabled=false", "transport_delay_samples=2"]),
        (  # controller period 2 ms on the 1 ms plant (eso_smc.k lowered: the set must validate)
            "ladrc",
            [
                "sample_time_s=0.002",
                "td.h=0.002",
                "linear.eso_smc.k=0.25",
                "rotary.eso_smc.k=0.0005",
            ],
        ),
        ("eso_smc", ["eso_smc.delay_compensation=true", "eso_smc.integral_anti_windup=false"]),
        ("eso_smc", ["transport_delay_samples=0", "td.enabled=false"]),
        ("eso_smc", ["rotary.eso_smc.friction_compensation=false", "transport_delay_samples=3"]),
        ("eso_smc_plus", ["eso_smc_plus.valve_linearisation=true"]),
        (
            "eso_smc_plus",
            ["eso_smc_plus.valve_linearisation=true", "eso_smc_plus.delay_compensation=true"],
        ),
        ("eso_smc_plus", ["linear.eso_smc_plus.linear_model=force"]),
        (
            "eso_smc_plus",
            ["rotary.eso_smc_plus.rotary_observer=speed", "eso_smc_plus.delay_compensation=true"],
        ),
        ("eso_smc_plus", ["eso_smc_plus.reference_derivatives=td", "transport_delay_samples=2"]),
        ("eso_smc_plus", ["linear.eso_smc_plus.friction_feedforward=false"]),
    ],
)
def test_algorithm_options(controller, sets):
    a, b = both(spec_of(controller=controller, sets=sets, seed=4))
    assert_same(a, b)


@pytest.mark.parametrize("controller", AXIS_ALGORITHMS)
@pytest.mark.parametrize("file", [PAPER, RETUNED], ids=["paper", "retuned"])
def test_rotary_angle_model(controller, file):
    sets = ["rotary_model=angle"]
    if controller == "eso_smc_plus":
        sets.append("eso_smc_plus.reference_derivatives=td")
    a, b = both(spec_of(axes=("rotary",), controller=controller, sets=sets, file=file))
    assert_same(a, b)


def test_angle_model_with_speed_observer_and_friction_in_the_angle_channel():
    sets = ["rotary_model=angle", "eso_smc_plus.rotary_observer=speed"]
    a, b = both(spec_of(axes=("rotary",), controller="eso_smc_plus", sets=sets))
    assert_same(a, b)
    a, b = both(spec_of(axes=("rotary",), controller="eso_smc", sets=["rotary_model=angle"]))
    assert_same(a, b)


# ------------------------------------------------------------------ seeds, start, length
@pytest.mark.parametrize("seed", [0, 7, 123])
def test_seeds_and_start_position(seed):
    a, b = both(spec_of(controller="eso_smc", seed=seed, duration_s=0.5))
    assert_same(a, b)
    spec = spec_of(axes=("linear",), controller="pid", seed=seed, duration_s=0.5)
    assert_same(*both(dataclasses.replace(spec, x0=0.02)))


def test_another_plant_period():
    from pneu_msgs_py.params.core import with_updates
    from pneu_sim.physics.plant_file import load_plant

    plant = with_updates(load_plant(), {"sim.T": 0.0005, "sim.n_sub": 5})
    a, b = both(spec_of(controller="eso_smc", plant=plant, duration_s=0.4))
    assert_same(a, b)
    assert b.t[1] == 0.0005


@pytest.mark.parametrize("duration_s", [0.01, 0.0105, 0.0125])  # the cap: >= 0.01 s
def test_tiny_runs(duration_s):
    a, b = both(spec_of(controller="ladrc", duration_s=duration_s))
    assert_same(a, b)


# ------------------------------------------------------------------ every supervisor rule
@pytest.mark.parametrize(
    ("overrides", "rule"),
    [
        ({"max_speed_rpm": 700.0}, "overspeed"),
        ({"stuck_ms": 1.5}, "stuck"),
        ({"pressure_live_v": (-0.3, 1.2)}, "live_range"),
        ({"laser_live_v": (-0.3, 2.55)}, "live_range"),
        ({"allow_unsafe": True, "pressure_margin_pa": -1.0e5}, "over_pressure"),
        ({"allow_unsafe": True, "position_margin_m": -0.07}, "position_range"),
        ({"max_accel_rad_s2": 1.0, "encoder_slack_counts": 0}, "encoder_jump"),
        ({"stall_inlet_pa": 1.2e5, "stall_ms": 2.0}, "no_rotation"),
        ({"stroke_margin_m": 0.066, "stroke_hyst_m": 0.0005}, "soft_limit"),
        ({"watchdog_ms": 0.5, "late_hold_ms": 0.0, "late_ramp_ms": 0.0}, "watchdog"),
        ({"late_policy": "trip"}, "command"),  # commands never late in process: no trip
        ({"late_policy": "ramp"}, "command"),
        ({"extend_above_neutral": False, "stroke_margin_m": 0.066}, "soft_limit"),
        (
            {"velocity_window_ms": 1.0, "speed_window_ms": 2.0, "max_speed_rpm": 650.0},
            "overspeed",
        ),
    ],
)
def test_each_supervisor_rule_acts_the_same(overrides, rule):
    # limits below the reference on purpose: build_spec would refuse them (checks.py), so
    # the supervisor is swapped in after the checks to make each rule act
    safety = SafetyParams(**overrides)
    spec = replace(spec_of(controller="eso_smc", seed=3, duration_s=0.8), safety=safety)
    a, b = both(spec)
    assert_same(a, b)
    assert any(e.rule == rule for e in b.safety_events), [e.rule for e in b.safety_events]


def angle_spec(plumbing, reference, duration_s=0.6, loads=None, **safety):
    """A rotary angle run with the controllers a task uses; the supervisor swapped in after
    the checks (a reference beyond the angle soft limits would be refused)."""
    from pneu_control.task.session import rotary_defaults
    from pneu_msgs_py.params.core import with_updates
    from pneu_sim.physics.plant_file import load_plant

    sets = ["rotary_control=angle", *(f"reference.{k}={v}" for k, v in reference.items())]
    defaults = rotary_defaults(plumbing)  # what a task runs with this plumbing
    alg = defaults["algorithm"]
    sets += [f"{k}={v}" for k, v in defaults.items() if k not in ("algorithm", "rotary_control")]
    updates = {"rotary.plumbing": plumbing, **{f"load.{k}": v for k, v in (loads or {}).items()}}
    sp = SafetyParams(rotary_plumbing=plumbing)
    spec = spec_of(
        axes=("rotary",), controller=alg, sets=sets, duration_s=duration_s,
        plant=with_updates(load_plant(), updates), safety=sp,
    )  # fmt: skip
    return replace(spec, safety=replace(sp, **safety))


RAMP = {"kind": "ramp", "offset": 0.0, "slope": 360.0}
LIMITED = {"angle_limits": True, "angle_min_deg": -100.0, "angle_max_deg": 100.0,
           "angle_margin_deg": 10.0}  # fmt: skip


@pytest.mark.parametrize("plumbing", ["paper", "bidirectional"])
@pytest.mark.parametrize(
    ("reference", "loads", "safety", "rules"),
    [
        (RAMP, None, LIMITED, {"soft_limit", "angle_limit"}),
        ({"kind": "constant", "value": 90.0}, {"T_bk": 10.0}, {}, {"no_rotation"}),
        ({"kind": "constant", "value": 720.0}, None, {"max_speed_rpm": 200.0}, {"overspeed"}),
        (RAMP, None, {"watchdog_ms": 0.5, "late_hold_ms": 0.0, "late_ramp_ms": 0.0}, {"watchdog"}),
        (RAMP, None, {"stuck_ms": 1.5}, {"stuck"}),
    ],
    ids=["angle-limits", "blocked", "overspeed", "watchdog", "stuck"],
)
def test_the_rules_act_the_same_in_rotary_angle_control(plumbing, reference, loads, safety, rules):
    """Angle control on both plumbings: the angle soft limits (hold and trip), the stalled
    rotation, and the rules that were there before, compiled = Python bit for bit."""
    a, b = both(angle_spec(plumbing, reference, loads=loads, **safety))
    assert_same(a, b)
    assert rules <= {e.rule for e in b.safety_events}, [e.rule for e in b.safety_events]


def test_allow_unsafe_reports_at_start():
    safety = SafetyParams(allow_unsafe=True, watchdog_ms=2000.0)
    a, b = both(spec_of(controller="pid", safety=safety, duration_s=0.2))
    assert_same(a, b)
    assert b.safety_events[0].rule == "allow_unsafe"


# ------------------------------------------------------------------ fallback and checks
def test_faults_run_in_python_and_say_why():
    spec = spec_of(controller="pid", faults=["sensor_dropout:sensor=x,start_s=0.2,duration_s=0.1"])
    reason = compiled_support(spec)
    assert reason and "fault" in reason
    told = []
    b = run_compiled(spec, on_fallback=told.append)
    assert told == [reason]
    assert_same(run(spec), b)
    with pytest.raises(ValueError, match="injected faults"):
        run_compiled(spec, fallback=False)


def test_a_compiled_output_that_differs_from_the_supervisor_is_caught(monkeypatch):
    """The event replay checks the compiled outputs: a corrupted one raises."""
    from pneu_control.fastloop import loop

    real = loop.closed_loop

    def corrupted(*args):
        status, k, last = real(*args)
        args[-1][10, 7] += 1e-9  # the held linear voltage of cycle 10
        return status, k, last

    monkeypatch.setattr(loop, "closed_loop", corrupted)
    spec = spec_of(controller="pid", file=PAPER, duration_s=0.3)  # trips: replay past cycle 10
    with pytest.raises(CompiledLoopMismatch, match="cycle 10"):
        run_compiled(spec, fallback=False)


def test_configs_are_fully_compiled():
    for file in (PAPER, RETUNED):
        for controller in AXIS_ALGORITHMS:
            assert compiled_support(spec_of(controller=controller, file=file)) is None
    assert compiled_mod.compiled_support.__doc__


def test_same_spec_same_bytes_in_one_process():
    spec = spec_of(controller="eso_smc_plus", duration_s=0.5, seed=9)
    a = run_compiled(spec, fallback=False)
    b = run_compiled(spec, fallback=False)
    for axis in a.axes:
        for k in a.axes[axis]:
            assert a.axes[axis][k].tobytes() == b.axes[axis][k].tobytes()
    assert a.metrics_dict() == b.metrics_dict() and len(a.t) == 500


def test_runs_in_threads_equal_runs_in_turn():
    """The loop releases the GIL; each run owns its arrays, so threads do not mix them."""
    from concurrent.futures import ThreadPoolExecutor

    specs = [spec_of(controller=c, duration_s=0.4, seed=i) for i, c in enumerate(AXIS_ALGORITHMS)]
    with ThreadPoolExecutor(max_workers=2) as pool:
        threaded = list(pool.map(lambda s: run_compiled(s, fallback=False), specs))
    for spec, b in zip(specs, threaded):
        assert_same(run_compiled(spec, fallback=False), b)


@pytest.mark.parametrize("controller", ["pid", "ladrc", "eso_smc", *ANGLE_ONLY_ALGORITHMS])
def test_rotary_angle_control_compiled(controller):
    """rotary_control: angle (a 360° step), every angle law, the supervisor on: same bits."""
    sets = ["rotary_control=angle", "reference.kind=constant", "reference.value=360.0"]
    if controller == "eso_smc":
        sets.append("eso_smc.friction_compensation=false")
    a, b = both(spec_of(axes=("rotary",), controller=controller, sets=sets, duration_s=0.6))
    assert_same(a, b)
    assert a.metrics["rotary"].unit == "°"
