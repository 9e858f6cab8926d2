"""Controller parameters: the paper's gains in config/controllers.yaml, bad input refused."""

import math
from dataclasses import replace
from pathlib import Path

import pytest
import yaml
from pneu_control.controller.axis import AxisController
from pneu_control.controller.params import (
    AxisControllerParams,
    ParamError,
    load_controller_params,
)
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.params.core import describe, with_updates

CONFIG = Path(__file__).resolve().parents[3] / "config" / "controllers.yaml"

# DESIGN §8 (paper, Results section)
PAPER = {
    "linear": {
        "pid.kp": 0.38,
        "pid.ki": 4.6,
        "pid.kd": 0.0128,
        "ladrc.lambda_1": 390.0,
        "ladrc.omega_0": 31.5,
        "ladrc.b_0": 5900.0,
        "eso_smc.lambda_r": 250.0,
        "eso_smc.omega_0": 25.0,
        "eso_smc.delta": 0.1,
        "eso_smc.b_0": 3000.0,
        "eso_smc.epsilon": 1200.0,
        "eso_smc.k": 0.5,
        "td.r": 50000.0,
        "td.h": 0.001,
    },
    "rotary": {
        "pid.kp": 0.25,
        "pid.ki": 0.22,
        "pid.kd": 0.004,
        "ladrc.lambda_1": 10.0,
        "ladrc.omega_0": 15.0,
        "ladrc.b_0": 500.0,
        "eso_smc.lambda_r": 250.0,
        "eso_smc.omega_0": 10.0,
        "eso_smc.delta": 0.1,
        "eso_smc.b_0": 500.0,
        "eso_smc.epsilon": 200.0,
        "eso_smc.k": 0.5,
        "td.r": 5000.0,
        "td.h": 0.001,
    },
}


def _get(obj, dotted):
    for part in dotted.split("."):
        obj = getattr(obj, part)
    return obj


@pytest.mark.parametrize("axis", ["linear", "rotary"])
def test_yaml_holds_the_papers_gains(axis):
    p = load_controller_params(axis, CONFIG)
    for key, value in PAPER[axis].items():
        assert _get(p, key) == value, key
    assert p.sample_time_s == 0.001 and p.limits.u_neutral == 5.0
    assert p.reference.kind == ("sine" if axis == "linear" else "constant")


def test_yaml_is_a_ros2_params_file_with_floats_as_floats():
    data = yaml.safe_load(CONFIG.read_text())
    assert set(data) == {"linear_controller", "rotary_controller"}
    floats = {s.name for s in describe(AxisControllerParams) if s.type is float}
    for node in data.values():
        params = node["ros__parameters"]

        def walk(d, prefix=""):
            for k, v in d.items():
                name = prefix + k
                if isinstance(v, dict):
                    yield from walk(v, name + ".")
                else:
                    yield name, v

        seen = dict(walk(params))
        assert floats <= set(seen), floats - set(seen)  # every float written out
        for name in floats:
            assert type(seen[name]) is float, f"{name}: {seen[name]!r} must be written as a float"


@pytest.mark.parametrize(
    ("override", "key", "allowed"),
    [
        ({"pid.kp": 0.0}, "pid.kp", r"\(0, inf\)"),
        ({"pid.kp": -0.38}, "pid.kp", r"\(0, inf\)"),
        ({"pid.ki": -1.0}, "pid.ki", r"\[0, inf\)"),
        ({"eso_smc.delta": 0.0}, "eso_smc.delta", r"\(0, inf\)"),
        ({"eso_smc.delta": -0.1}, "eso_smc.delta", r"\(0, inf\)"),
        ({"eso_smc.epsilon": 0.0}, "eso_smc.epsilon", r"\(0, inf\)"),
        ({"ladrc.b_0": -5900.0}, "ladrc.b_0", r"\(0, inf\)"),
        ({"ladrc.omega_0": 0.0}, "ladrc.omega_0", r"\(0, π/sample_time_s\] rad/s.*3141.59"),
        ({"td.r": 0.0}, "td.r", r"\(0, inf\)"),
        ({"algorithm": "fuzzy"}, "algorithm", "one of pid, ladrc, eso_smc"),
        ({"reference.kind": "square"}, "reference.kind", "one of sine, smooth_step"),
        ({"reference.frequency_hz": 600.0}, "reference.frequency_hz", r"\(0, 500\) Hz"),
        ({"reference.frequency_hz": 500.0}, "reference.frequency_hz", r"\(0, 500\) Hz"),
        ({"eso_smc.omega_0": 4000.0}, "eso_smc.omega_0", r"\(0, 3141.59\] rad/s"),
        ({"ladrc.omega_0": 3200.0}, "ladrc.omega_0", r"\(0, 3141.59\] rad/s"),
        ({"td.h": 0.0005}, "td.h", r"\[0.001, inf\) s"),
        ({"pid.anti_windup": "clamp"}, "pid.anti_windup", "conditional, back_calculation, none"),
    ],
)
def test_bad_values_refused_naming_key_value_and_range(override, key, allowed):
    p = load_controller_params("linear", CONFIG)
    with pytest.raises(ParamError, match=allowed) as err:
        with_updates(p, override)
    assert err.value.key == key
    assert str(err.value).startswith(f"{key}: {next(iter(override.values()))!r} refused")
    with pytest.raises(ParamError, match=allowed):  # the loader path refuses the same way
        load_controller_params("linear", CONFIG, override)


@pytest.mark.parametrize(
    "override, key, allowed",
    [
        ({"eso_smc.k": 20.0}, "eso_smc.k/eso_smc.delta", r"k in \(0, 10\] at Δ = 0.1, or Δ in"),
        ({"eso_smc.k": 10.0}, "eso_smc.epsilon/eso_smc.k", r"ε·k·T < 1 .*: k in \(0, 0.833333\)"),
        # ε set, k as the file has it: the line names ε too, and its range at that k
        ({"eso_smc.epsilon": 2000.0}, "eso_smc.epsilon/eso_smc.k", r"or ε in \(0, 2000\) at k"),
    ],
)
def test_coupled_fields_are_refused_naming_both(override, key, allowed):
    p = load_controller_params("linear", CONFIG)
    with pytest.raises(ParamError, match=allowed) as err:
        with_updates(p, override)
    assert err.value.key == key


def test_sine_zero_frequency_and_step_zero_duration_refused():
    p = load_controller_params("linear", CONFIG)
    with pytest.raises(ParamError, match=r"^reference.frequency_hz: 0.0 refused"):
        with_updates(p, {"reference.frequency_hz": 0.0})
    with pytest.raises(ParamError, match=r"^reference.duration_s: 0.0 refused"):
        with_updates(p, {"reference.kind": "smooth_step", "reference.duration_s": 0.0})


def test_friction_smoothing_bound_and_linear_axis_refusal():
    p = load_controller_params("rotary", CONFIG)
    with pytest.raises(ParamError, match=r"^eso_smc.coulomb_smoothing: 20.0 refused; allowed: \(3"):
        with_updates(p, {"eso_smc.coulomb_smoothing": 20.0})
    lin = with_updates(
        load_controller_params("linear", CONFIG), {"eso_smc.friction_compensation": True}
    )
    with pytest.raises(ParamError, match="eso_smc.friction_compensation"):
        AxisController("linear", lin)


def test_overrides_apply_as_one_set_and_coerce_ints():
    p = load_controller_params("linear", CONFIG, {"eso_smc.epsilon": 900, "algorithm": "ladrc"})
    assert p.eso_smc.epsilon == 900.0 and type(p.eso_smc.epsilon) is float
    assert p.algorithm == "ladrc"
    # each valid alone, not together: ε·k·T = 2000·0.6·0.001 ≥ 1
    with pytest.raises(ParamError, match="eso_smc.k"):
        load_controller_params("linear", CONFIG, {"eso_smc.epsilon": 2000.0, "eso_smc.k": 0.6})


def test_unknown_axis_and_section_refused(tmp_path):
    with pytest.raises(ParamError, match="axis"):
        load_controller_params("vertical", CONFIG)
    f = tmp_path / "c.yaml"
    f.write_text("linear_controller:\n  ros__parameters:\n    algorithm: pid\n")
    with pytest.raises(ParamError, match="rotary_controller"):
        load_controller_params("rotary", f)
    with pytest.raises(
        ParamError, match=r"c\.yaml:3:5: pid: missing; required: the parameter group kp"
    ):
        load_controller_params("linear", f)  # missing keys refused, as in every config file
    f.write_text(Path(CONFIG).read_text().replace("      kp: 0.38", "      kq: 0.38", 1))
    with pytest.raises(ParamError, match=r"c\.yaml:\d+:7: pid.kq: 0.38 refused; allowed: no such"):
        load_controller_params("linear", f)


def _sample(k, x=0.0, omega=0.0):
    return SensorSample(k, k * 1_000_000, 2e5, 2e5, 2e5, x, 0.0, omega, 0)


def test_running_controller_keeps_old_params_on_refusal():
    p = load_controller_params("linear", CONFIG)
    a, b = AxisController("linear", p), AxisController("linear", p)
    # built without validation (dataclasses.replace): set_params must validate itself
    bad_pid = replace(p, algorithm="pid", pid=replace(p.pid, kp=-1.0))
    slower = replace(p, sample_time_s=0.002)
    for k in range(300):
        x = 1e-3 * math.sin(0.01 * k)
        if k == 100:
            with pytest.raises(ParamError, match=r"^pid.kp: -1.0 refused"):
                a.set_params(bad_pid)
            with pytest.raises(
                ParamError, match="sample_time_s: 0.002 refused; allowed: read-only"
            ):
                a.set_params(slower)
            with pytest.raises(ParamError, match="reference.file"):
                a.set_params(
                    with_updates(
                        p, {"reference.kind": "waypoints", "reference.file": "/nonexistent.csv"}
                    )
                )
        assert a.update(_sample(k, x)) == b.update(_sample(k, x))
    assert a.params == p and a.algorithm == "eso_smc"


def test_real_controller_params_declare_and_round_trip_for_both_axes():
    """pneu_control's parameters through pneu_msgs_py's ROS descriptor plumbing (rosbags'
    Jazzy rcl_interfaces types stand in for rclpy's)."""
    from pneu_msgs_py.params.core import flatten
    from pneu_msgs_py.params.ros import PARAMETER_TYPE, declarations, validate_updates
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    ParameterDescriptor = ts.types["rcl_interfaces/msg/ParameterDescriptor"]
    FloatingPointRange = ts.types["rcl_interfaces/msg/FloatingPointRange"]
    IntegerRange = ts.types["rcl_interfaces/msg/IntegerRange"]
    for axis in ("linear", "rotary"):
        params = load_controller_params(axis)
        decls = declarations(params, ParameterDescriptor, FloatingPointRange, IntegerRange)
        assert [n for n, _, _ in decls] == list(flatten(params))
        for name, value, desc in decls:
            assert desc.type == PARAMETER_TYPE[type(value)], (
                name
            )  # what rclpy infers from the value
            for r in desc.floating_point_range:  # the loaded value is inside its descriptor range
                assert r.from_value <= value <= r.to_value, name
        ok, reason, again = validate_updates(params, [(n, v) for n, v, _ in decls], startup=True)
        assert ok, reason
        assert again == params
        ro = {n for n, _, d in decls if d.read_only}
        assert {"sample_time_s", "transport_delay_samples"} <= ro


def test_a_relation_of_three_limits_names_all_three():
    with pytest.raises(ParamError) as err:
        load_controller_params("linear", CONFIG, {"limits.u_neutral": 10.0})
    assert str(err.value).startswith("limits.u_min/u_neutral/u_max: '0/10/10 V' refused")
    with pytest.raises(ParamError, match=r"^limits.u_min/u_neutral/u_max: '0/5/0 V'"):
        load_controller_params("linear", CONFIG, {"limits.u_max": 0.0})
