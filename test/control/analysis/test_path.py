"""Path error: distance to the intended x–θ curve (timing-free) and the per-joint errors."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from pneu_control.analysis import path as path_mod
from pneu_control.analysis.path import analyse_path, curve, joint_errors, path_distances
from pneu_control.controller.trajectory import (
    insert_then_twist,
    joint_reference,
    screw,
    twist_while_retracting,
)
from pneu_msgs_py.params.core import ParamError

RNG = np.random.default_rng(20261203)
TWO_PI = 2.0 * math.pi


def _eval(traj, ts):
    x, th = joint_reference(traj, "linear"), joint_reference(traj, "rotary")
    return np.array([x(t)[0] for t in ts]), np.array([th(t)[0] for t in ts])


def _screw():
    return screw(-0.01, 0.2, 0.002, 3.0, 1.0, 0.25)  # 2 mm pitch, 1 turn/s


def test_the_intended_screw_has_no_path_error():
    tr = _screw()
    t = np.sort(RNG.uniform(-0.5, tr.t_end + 0.5, 5000))  # off the curve's sample times
    x, th = _eval(tr, t)
    d = path_distances(tr, x, th)
    assert d.max() < 1e-9
    rep = analyse_path(tr, t, x, th)
    assert rep.r_eq_m == pytest.approx(0.002 / TWO_PI)
    assert rep.path_max_mm < 1e-6 and rep.joints["linear"].e_max == 0.0
    assert rep.joints["rotary"].rmse == 0.0 and rep.n_samples == 5000


def test_a_constant_linear_offset_on_a_twist_is_the_path_error():
    tr = insert_then_twist(-0.02, 0.03, 0.0, 2 * math.pi, 0.5, 1.0, dwell=0.2)
    t = np.linspace(0.8, 1.6, 801)  # inside the pure rotation (0.7 – 1.7 s)
    x, th = _eval(tr, t)
    rep = analyse_path(tr, t, x + 0.0005, th, r_eq_m=0.01)
    assert rep.path_max_mm == pytest.approx(0.5, abs=1e-9)
    assert rep.path_rms_mm == pytest.approx(0.5, abs=1e-9)
    e = rep.joints["linear"]
    assert (e.e_max, e.rmse, e.final) == pytest.approx((0.0005, 0.0005, -0.0005), abs=1e-15)
    assert rep.joints["rotary"].e_max == 0.0


def test_an_offset_across_the_screw_thread_is_seen_at_45_degrees():
    # with r_eq = p/(2π) the helix is the line x − x0 = r_eq (θ − θ0): slope 1 in (x, r_eq θ),
    # so an axial offset d sits d/√2 from it
    tr = _screw()
    t = np.linspace(0.5, 3.0, 500)
    x, th = _eval(tr, t)
    d = path_distances(tr, x - 0.0003, th)
    assert d == pytest.approx(np.full_like(d, 0.0003 / math.sqrt(2.0)), abs=1e-12)


def test_a_lag_along_the_path_is_free_of_path_error_but_not_of_joint_error():
    tr = _screw()
    lag = 0.05
    t = np.arange(0.0, tr.t_end + 0.5, 0.001)
    x, th = _eval(tr, t - lag)
    rep = analyse_path(tr, t, x, th)
    assert rep.path_max_mm < 1e-6
    # in the cruise the lag costs ω·lag on the angle and (p/2π)·ω·lag on x, exactly
    assert rep.joints["rotary"].e_max == pytest.approx(TWO_PI * 1.0 * lag, rel=1e-9)
    assert rep.joints["linear"].e_max == pytest.approx(0.002 * lag, rel=1e-9)
    assert abs(rep.joints["rotary"].final) < 1e-12  # both caught up at the end
    line = rep.summary()
    assert "path (r_eq = 0.3183 mm/rad)" in line and "rotary: e_max 18 deg" in line


def test_chunked_distance_equals_a_naive_loop_on_a_curved_path(monkeypatch):
    # twist leads: the x–θ curve bends; compare with the plain point-to-segment loop
    tr = twist_while_retracting(0.03, -0.04, 0.0, 3 * math.pi, 2.0, twist_lead=0.7)
    r_eq = 0.005
    t = RNG.uniform(0.0, 2.0, 60)
    x, th = _eval(tr, t)
    x = x + RNG.normal(0.0, 0.001, t.size)
    th = th + RNG.normal(0.0, 0.1, t.size)
    verts = curve(tr, r_eq, n_curve=300)
    want = []
    for q in zip(x, r_eq * th):
        best = math.inf
        for a, b in itertools.pairwise(verts):
            d = b - a
            u = min(max(float(np.dot(np.subtract(q, a), d) / np.dot(d, d)), 0.0), 1.0)
            best = min(best, math.dist(q, a + u * d))
        want.append(best)
    monkeypatch.setattr(path_mod, "_CHUNK", 700)  # blocks of 2 points (300 segments)
    got = path_distances(tr, x, th, r_eq_m=r_eq, n_curve=300)
    assert got == pytest.approx(want, rel=1e-12, abs=1e-15)
    assert max(want) > 0.0005  # the noise is visible, the test can fail


def test_curve_resolution_converges():
    # the dense polyline's chord error on the bent path shrinks with n_curve
    tr = twist_while_retracting(0.03, -0.04, 0.0, 3 * math.pi, 2.0, twist_lead=0.7)
    t = np.linspace(0.0, 2.0, 777)
    x, th = _eval(tr, t)
    coarse = path_distances(tr, x, th, r_eq_m=0.005, n_curve=20).max()
    fine = path_distances(tr, x, th, r_eq_m=0.005, n_curve=4000).max()
    assert coarse > 1e-6 and fine < 1e-8


def test_r_eq_needed_where_the_shape_gives_none_and_shapes_checked():
    tr = insert_then_twist(0.0, 0.01, 0.0, 1.0, 0.5, 0.5)
    t = np.linspace(0.0, 1.0, 11)
    x, th = _eval(tr, t)
    with pytest.raises(ParamError, match=r"^r_eq_m: None refused; allowed: \(0, inf\) m per rad"):
        analyse_path(tr, t, x, th)
    with pytest.raises(ParamError, match=r"^r_eq_m: -1\.0 refused"):
        path_distances(tr, x, th, r_eq_m=-1.0)
    with pytest.raises(ParamError, match=r"^theta: None refused; allowed: measured rotary"):
        joint_errors(tr, t, x)
    with pytest.raises(ParamError, match=r"^x: \(10,\) refused; allowed: the shape of t, \(11,\)"):
        joint_errors(tr, t, x[:-1], th)
