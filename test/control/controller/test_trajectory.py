"""Two-axis trajectories: the Hermite through the points, C², the shapes, limits, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit
from pneu_control.controller.references import REFERENCE, Waypoints, reference_at
from pneu_control.controller.trajectory import (
    JointTrajectory,
    TrajectoryPoint,
    check_limits,
    from_dict,
    insert_then_twist,
    joint_reference,
    screw,
    to_dict,
    twist_while_retracting,
)
from pneu_driver.safety.params import load_safety_params
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.records import JIT

RNG = np.random.default_rng(20261202)
TWO_PI = 2.0 * math.pi


def _traj(points, names=("linear", "rotary")):
    return JointTrajectory(names, tuple(TrajectoryPoint(**p) for p in points))


# interior velocities given at points 1 and 3, none at 2 (Fritsch–Carlson there)
GIVEN = [
    {"time_from_start": 0.2, "positions": (0.0, 0.0)},
    {"time_from_start": 0.7, "positions": (0.01, 1.0), "velocities": (0.03, 4.0)},
    {"time_from_start": 1.1, "positions": (0.02, 2.5)},
    {"time_from_start": 1.8, "positions": (0.005, 6.0), "velocities": (-0.02, 5.5)},
    {"time_from_start": 2.5, "positions": (0.0, 7.0), "velocities": (0.0, 0.0)},
]


def _fd(ref, t, h=1e-6):
    (r_m, rd_m, _), (r_p, rd_p, _) = ref(t - h), ref(t + h)
    return (r_p - r_m) / (2 * h), (rd_p - rd_m) / (2 * h)


def test_hermite_passes_through_points_with_the_given_velocities():
    tr = _traj(GIVEN)
    for j, name in enumerate(("linear", "rotary")):
        ref = joint_reference(tr, name)
        assert isinstance(ref, Waypoints)  # the existing kernel evaluates it
        for i, p in enumerate(GIVEN):
            r, rd, _ = ref(p["time_from_start"])
            assert r == pytest.approx(p["positions"][j], abs=1e-15)
            if 0 < i < len(GIVEN) - 1 and "velocities" in p:
                assert rd == pytest.approx(p["velocities"][j], rel=1e-12, abs=1e-15)
        # the derivative just inside each interior knot matches the given velocity too
        for i in (1, 3):
            t = GIVEN[i]["time_from_start"]
            for s in (-1e-7, 1e-7):
                assert ref(t + s)[1] == pytest.approx(GIVEN[i]["velocities"][j], rel=1e-5)


def test_absent_velocities_follow_the_waypoints_rule_bit_for_bit():
    pts = [{"time_from_start": p["time_from_start"], "positions": p["positions"]} for p in GIVEN]
    tr = _traj(pts)
    for j, name in enumerate(("linear", "rotary")):
        ref = joint_reference(tr, name)
        w = Waypoints([p["time_from_start"] for p in pts], [p["positions"][j] for p in pts])
        assert ref.knots == w.knots
        ts = RNG.uniform(-0.5, 3.0, 500).tolist()
        assert [ref(t) for t in ts] == [w(t) for t in ts]


def test_mixed_points_use_central_difference_accelerations_of_the_merged_velocities():
    ref = joint_reference(_traj(GIVEN), "rotary")
    t, v, a = ref.knots[0], ref.knots[2], ref.knots[3]
    assert v[1] == 4.0 and v[3] == 5.5 and v[0] == v[4] == 0.0
    # point 2 (no velocity): Fritsch–Carlson on its neighbours' secants (2.5-1)/0.4, (6-2.5)/0.7
    d0, d1, h0, h1 = 1.5 / 0.4, 3.5 / 0.7, 0.4, 0.7
    w1, w2 = 2 * h1 + h0, h1 + 2 * h0
    assert v[2] == pytest.approx((w1 + w2) / (w1 / d0 + w2 / d1))
    for i in (1, 2, 3):
        assert a[i] == pytest.approx((v[i + 1] - v[i - 1]) / (t[i + 1] - t[i - 1]))
    assert a[0] == a[4] == 0.0


def test_given_accelerations_are_used():
    pts = [dict(p) for p in GIVEN]
    pts[2]["velocities"] = (0.04, 3.0)
    pts[2]["accelerations"] = (0.1, -2.0)
    ref = joint_reference(_traj(pts), "linear")
    r, rd, rdd = ref(1.1)
    assert (r, rd) == pytest.approx((0.02, 0.04), abs=1e-15)
    assert rdd == pytest.approx(0.1, rel=1e-12)


@pytest.mark.parametrize("name", ["linear", "rotary"])
def test_reference_is_c2(name):
    ref = joint_reference(_traj(GIVEN), name)
    scale = 1.0 if name == "rotary" else 0.01
    for t in np.linspace(0.25, 2.45, 41):  # derivatives are derivatives
        rd_fd, rdd_fd = _fd(ref, t)
        _, rd, rdd = ref(t)
        assert rd_fd == pytest.approx(rd, abs=1e-6 * scale * 10)
        assert rdd_fd == pytest.approx(rdd, abs=1e-4 * scale * 10)
    for p in GIVEN:  # r, ṙ, r̈ continuous across every point
        t = p["time_from_start"]
        lo, hi = ref(t - 1e-9), ref(t + 1e-9)
        for x, y, tol in zip(lo, hi, (1e-8, 1e-6, 1e-3)):
            assert x == pytest.approx(y, abs=tol * scale * 10)


def test_holds_the_first_point_before_and_the_last_after():
    ref = joint_reference(_traj(GIVEN), "rotary")
    assert ref(0.0) == (0.0, 0.0, 0.0) and ref(-5.0) == (0.0, 0.0, 0.0)
    assert ref(2.5) == (7.0, 0.0, 0.0) and ref(100.0) == (7.0, 0.0, 0.0)


@njit(**JIT)
def _ref_many(rc, knots, ts, out):
    for i in range(ts.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = reference_at(rc[0], knots, ts[i])


def _bits(values):
    return np.asarray(values, dtype=np.float64).view(np.int64).tolist()


@pytest.mark.parametrize("which", ["given", "screw"])
def test_compiled_kernel_equals_python_bit_for_bit(which):
    tr = _traj(GIVEN) if which == "given" else screw(0.0, 0.3, 0.002, 2.0, 1.0, 0.3)
    for name in tr.joint_names:
        py = joint_reference(tr, name)
        rc = REFERENCE.array(1)
        py.rc.store(rc[0])
        knots = np.array(py.knots, dtype=np.float64)
        ts = np.concatenate(
            [np.arange(-0.1, tr.t_end + 0.1, 0.001), RNG.uniform(-1.0, tr.t_end + 1.0, 2000)]
        )
        got = np.empty((len(ts), 3))
        _ref_many(rc, knots, ts, got)
        assert _bits(got) == _bits([py(t) for t in ts.tolist()])


# --- shapes -----------------------------------------------------------------------------------


def test_screw_lies_on_the_helix_and_cruises_at_the_rate():
    x0, th0, p, turns, rate, ramp = -0.01, 0.5, 0.004, 3.0, 1.0, 0.25
    tr = screw(x0, th0, p, turns, rate, ramp)
    x, th = joint_reference(tr, "linear"), joint_reference(tr, "rotary")
    assert tr.r_eq_m == pytest.approx(p / TWO_PI)
    t_end = turns / rate + ramp
    assert tr.t_end == pytest.approx(t_end)
    ts = np.linspace(-0.2, t_end + 0.2, 20001).tolist()
    for t in ts:  # x = x0 + p (θ − θ0)/(2π), and so for the derivatives
        (xr, xd, xdd), (tr_, td, tdd) = x(t), th(t)
        assert xr == pytest.approx(x0 + p * (tr_ - th0) / TWO_PI, abs=1e-15)
        assert xd == pytest.approx(p * td / TWO_PI, abs=1e-15)
        assert xdd == pytest.approx(p * tdd / TWO_PI, abs=1e-13)
    w = TWO_PI * rate
    th_c = th0 + 0.5 * w * ramp  # after the ramp: half the cruise speed times its length
    for t in np.linspace(ramp, t_end - ramp, 777).tolist():  # the cruise is the line, exactly
        r, rd, rdd = th(t)
        assert r == pytest.approx(th_c + w * (t - ramp), abs=1e-12)
        assert rd == pytest.approx(w, abs=1e-12) and rdd == pytest.approx(0.0, abs=1e-9)
    assert th(t_end) == (th0 + TWO_PI * turns, 0.0, 0.0)
    assert x(t_end)[0] == pytest.approx(x0 + p * turns, abs=1e-15)
    # the ramp: φ̇ = ω (3u² − 2u³), φ̈ = 6ω u(1 − u)/ramp, at rest at both ends
    for u in (0.1, 0.5, 0.9):
        _, rd, rdd = th(ramp * u)
        assert rd == pytest.approx(w * (3 * u * u - 2 * u**3), rel=1e-12)
        assert rdd == pytest.approx(6 * w * u * (1 - u) / ramp, rel=1e-10)
        _, rd_e, rdd_e = th(t_end - ramp * u)
        assert rd_e == pytest.approx(rd, rel=1e-10) and rdd_e == pytest.approx(-rdd, rel=1e-9)


def test_screw_backwards_and_negative_pitch():
    tr = screw(0.02, 0.0, -0.003, -2.0, 0.5)
    x, th = joint_reference(tr, "linear"), joint_reference(tr, "rotary")
    assert th(tr.t_end)[0] == pytest.approx(-2 * TWO_PI)
    assert x(tr.t_end)[0] == pytest.approx(0.02 + 0.006)
    assert th(2.0)[1] == pytest.approx(-0.5 * TWO_PI)


def test_insert_then_twist_moves_one_joint_at_a_time():
    tr = insert_then_twist(-0.02, 0.03, 0.1, math.pi, 0.8, 0.6, dwell=0.3, t0=0.5)
    x, th = joint_reference(tr, "linear"), joint_reference(tr, "rotary")
    assert tr.t_start == 0.5 and tr.t_end == pytest.approx(0.5 + 0.8 + 0.3 + 0.6)
    for t in np.linspace(0.0, 1.6, 300).tolist():
        assert th(t) == pytest.approx((0.1, 0.0, 0.0), abs=1e-15)
    for t in np.linspace(1.3, 3.0, 300).tolist():
        assert x(t) == pytest.approx((0.01, 0.0, 0.0), abs=1e-15)
    # minimum-jerk: halfway at the middle, peak speed 1.875 Δ/T there
    assert x(0.9) == pytest.approx((-0.005, 1.875 * 0.03 / 0.8, 0.0), abs=1e-12)
    assert th(1.9)[:2] == pytest.approx((0.1 + math.pi / 2, 1.875 * math.pi / 0.6), abs=1e-12)
    u = 0.3  # s(u) = 10u³ − 15u⁴ + 6u⁵ in between the points
    assert x(0.5 + 0.8 * u)[0] == pytest.approx(
        -0.02 + 0.03 * (10 * u**3 - 15 * u**4 + 6 * u**5), abs=1e-15
    )


def test_twist_while_retracting_leads_with_the_twist_and_ends_together():
    tr = twist_while_retracting(0.03, -0.04, 0.0, 3 * math.pi, 2.0, twist_lead=0.5)
    x, th = joint_reference(tr, "linear"), joint_reference(tr, "rotary")
    for t in np.linspace(0.0, 0.5, 50).tolist():
        assert x(t)[:2] == pytest.approx((0.03, 0.0), abs=1e-15)
    assert th(0.25)[1] > 0.0
    assert x(1.25)[:2] == pytest.approx((0.01, -1.875 * 0.04 / 1.5), abs=1e-12)
    assert th(1.0)[:2] == pytest.approx((1.5 * math.pi, 1.875 * 3 * math.pi / 2.0), abs=1e-12)
    assert x(2.0) == pytest.approx((-0.01, 0.0, 0.0)) and th(2.0)[0] == pytest.approx(3 * math.pi)


# --- limits and validation --------------------------------------------------------------------


def test_limits_come_from_safety_yaml():
    s = load_safety_params()  # the project's config/safety.yaml, read independently
    half = s.stroke_m / 2 - s.stroke_margin_m
    assert half == pytest.approx(0.065)
    with pytest.raises(ParamError, match=r"^screw\.turns: 7\.0 refused; allowed: x0 \+ pitch_m\*turns within \(-0\.065, 0\.065\) m"):  # fmt: skip
        screw(0.0, 0.0, 0.01, 7.0, 1.0, safety=s)
    rate = s.max_speed_rpm / 60.0
    screw(0.0, 0.0, 0.0001, 30.0, rate, safety=s)  # exactly at max_speed_rpm passes
    with pytest.raises(ParamError, match=r"^screw\.rate_turns_per_s: 26\.0 refused; .*max_speed_rpm = 1500"):  # fmt: skip
        screw(0.0, 0.0, 0.0001, 30.0, 26.0, safety=s)
    with pytest.raises(ParamError, match=r"^insert_then_twist\.t_twist: 0\.01 refused"):
        insert_then_twist(0.0, 0.01, 0.0, 2 * math.pi, 1.0, 0.01, safety=s)
    with pytest.raises(ParamError, match=r"^twist_while_retracting\.dx: -0\.07 refused"):
        twist_while_retracting(0.0, -0.07, 0.0, 1.0, 1.0, safety=s)


def test_braking_distance_counts_towards_the_stroke_limit():
    # -60 → +60 mm, inside the limits, in 0.1 s: 2.25 m/s peak, x + v²/(2·20 m/s²) reaches 133 mm
    with pytest.raises(ParamError, match=r"^points\[\d+\]\.positions\[0\]: .* braking distance"):
        insert_then_twist(-0.06, 0.12, 0.0, 1.0, 0.1, 1.0)
    insert_then_twist(-0.06, 0.12, 0.0, 1.0, 0.5, 1.0)  # slower: x + braking stays at 60 mm


def test_check_limits_names_the_point_of_a_too_fast_rotation():
    tr = _traj(
        [
            {"time_from_start": 0.0, "positions": (0.0, 0.0)},
            {"time_from_start": 1.0, "positions": (0.0, 1.0)},
            {"time_from_start": 1.1, "positions": (0.0, 30.0)},  # ~ 290 rad/s > 157
            {"time_from_start": 3.0, "positions": (0.0, 31.0)},
        ]
    )
    with pytest.raises(ParamError, match=r"^points\[1\]\.velocities\[1\]: .*max_speed_rpm = 1500"):
        check_limits(tr)


def _d(points, names=("linear", "rotary"), **extra):
    return {"joint_names": list(names), "points": points, **extra}


P0 = {"time_from_start": 0.0, "positions": [0.0, 0.0]}


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (
            _d([P0, {"time_from_start": 0.4, "positions": [0, 1]}, {"time_from_start": 0.8, "positions": [0, 2]}, {"time_from_start": 0.5, "positions": [0, 3]}]),
            r"^points\[3\]\.time_from_start: 0\.5 refused; allowed: > 0\.8 s \(strictly increasing\)$",
        ),
        (_d([{"time_from_start": -0.1, "positions": [0, 0]}]), r"^points\[0\]\.time_from_start: -0\.1 refused; allowed: >= 0 s$"),
        (_d([P0, {"time_from_start": 1.0, "positions": [0.0]}]), r"^points\[1\]\.positions: \(0\.0,\) refused; allowed: 2 values, one per joint \(linear, rotary\)$"),
        (_d([P0, {"time_from_start": 1.0, "positions": [0.0, float("nan")]}]), r"^points\[1\]\.positions\[1\]: nan refused; allowed: a finite number \(rad, joint rotary\)$"),
        (_d([P0, {"time_from_start": 1.0, "positions": [0.0, 1.0], "velocities": [0.0, 0.5]}]), r"^points\[1\]\.velocities\[1\]: 0\.5 refused; allowed: 0 at the first and last point"),
        (_d([P0, {"time_from_start": 1.0, "positions": [0.0, 1.0], "velocities": [0.1]}, P0 | {"time_from_start": 2.0}]), r"^points\[1\]\.velocities: \(0\.1,\) refused; allowed: 2 values, one per joint \(linear, rotary\), or none$"),
        (_d([P0], names=("linear", "torque")), r"^joint_names: \['linear', 'torque'\] refused; allowed: a non-empty subset of linear, rotary"),
        (_d([P0], names=("rotary", "rotary")), r"^joint_names: .* each once$"),
        (_d([]), r"^points: \[\] refused; allowed: at least one point$"),
        (_d([P0 | {"effort": [1, 2]}]), r"^points\[0\]\.effort: \[1, 2\] refused; allowed: no such key"),
        (_d([{"positions": [0, 0]}]), r"^points\[0\]\.time_from_start: missing"),
        (_d([P0], speed=3), r"^speed: 3 refused; allowed: no such key"),
        (_d([P0, {"time_from_start": 1.0, "positions": {"linear_in": 1.0, "rotary_deg": 5.0}}]), r"^points\[1\]\.positions\.linear_in: 1\.0 refused; allowed: one key per joint, of linear_m, linear_mm, rotary_rad, rotary_deg, rotary_turns"),
        (_d([P0, {"time_from_start": 1.0, "positions": {"linear_mm": 1.0}}]), r"^points\[1\]\.positions\.rotary_<unit>: missing"),
        (_d([P0, {"time_from_start": 1.0, "positions": [0.07, 0.0]}]), r"^points\[0\]\.positions\[0\]: .* within \(-0\.065, 0\.065\) m"),
    ],
)  # fmt: skip
def test_bad_trajectories_refused_with_one_line_naming_the_field(data, match):
    with pytest.raises(ParamError, match=match) as e:
        from_dict(data)
    assert "\n" not in str(e.value)


def test_from_dict_units_at_the_edge_and_round_trip():
    data = _d(
        [
            {"time_from_start": 0.0, "positions": {"rotary_deg": 0.0, "linear_mm": -5.0}},
            {
                "time_from_start": 1.0,
                "positions": {"linear_mm": 5.0, "rotary_turns": 0.5},
                "velocities": {"linear_mm": 10.0, "rotary_deg": 180.0},
            },
            {"time_from_start": 2.0, "positions": {"linear_m": 0.015, "rotary_rad": 2 * math.pi}},
        ]
    )
    tr = from_dict(data)
    assert tr.points[1].positions == pytest.approx((0.005, math.pi))
    assert tr.points[1].velocities == pytest.approx((0.01, math.pi))
    si = _d(
        [
            {"time_from_start": 0.0, "positions": [-0.005, 0.0]},
            {"time_from_start": 1.0, "positions": [0.005, math.pi], "velocities": [0.01, math.pi]},
            {"time_from_start": 2.0, "positions": [0.015, 2 * math.pi]},
        ]
    )
    for a, b in zip(from_dict(si).points, tr.points, strict=True):
        assert a.time_from_start == b.time_from_start
        assert a.positions == pytest.approx(b.positions, abs=1e-15)
        assert a.velocities == pytest.approx(b.velocities, abs=1e-15)
    sc = screw(0.0, 0.0, 0.002, 1.0, 1.0)
    assert from_dict(to_dict(sc)) == sc


def test_single_joint_trajectory():
    tr = from_dict(
        {
            "joint_names": ["rotary"],
            "points": [
                {"time_from_start": 0.0, "positions": [0.0]},
                {"time_from_start": 2.0, "positions": {"rotary_turns": 1.0}},
            ],
        }
    )
    assert joint_reference(tr, "rotary")(2.0)[0] == pytest.approx(TWO_PI)
    with pytest.raises(ParamError, match=r"^joint: 'linear' refused; allowed: one of rotary$"):
        joint_reference(tr, "linear")
