"""Closed-loop behaviour of AxisController on simple plants written here.

Plants (SI, the controller converts to mm/rpm): a double integrator
ÿ = b (u − 5 V) − c ẏ + d(t), exact ZOH when c = 0, with the one-sample
transport delay of DESIGN §3 (command of sample k applied on [k+d, k+d+1]),
optionally blocked (held still) for a while.
"""

import math

import numpy as np
import pytest
from pneu_control.controller.axis import STATE_FIELDS, AxisController, ControllerState
from pneu_control.controller.params import load_controller_params
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.params.core import with_updates

T = 0.001
RPM = 60.0 / (2.0 * math.pi)


class Plant:
    def __init__(self, axis, b, c=0.0, d=None, delay=1, y0=0.0, blocked=None):
        self.axis, self.b, self.c, self.delay = axis, b, c, delay
        self.d = d or (lambda t: 0.0)
        self.blocked = blocked or (lambda t: False)
        self.y, self.v = y0, 0.0

    def run(self, ctrl, n, hook=None):
        q = [5.0] * self.delay
        out = {name: np.empty(n) for name in ("y", "u", *STATE_FIELDS)}
        for k in range(n):
            if hook:
                hook(k, ctrl)
            lin = self.axis == "linear"
            s = SensorSample(
                k,
                k * 1_000_000,
                2e5,
                2e5,
                2e5,
                self.y if lin else 0.0,
                0.0,
                0.0 if lin else self.y,
                0,
            )
            u = ctrl.update(s)
            out["y"][k], out["u"][k] = self.y, u
            st = ctrl.state
            for name in STATE_FIELDS:
                out[name][k] = getattr(st, name)
            q.append(u)
            ua = q.pop(0)
            t = k * T
            if self.blocked(t):
                self.v = 0.0
                continue
            if self.c == 0.0:
                a = self.b * (ua - 5.0) + self.d(t)
                self.y += T * self.v + 0.5 * T * T * a
                self.v += T * a
            else:
                h = T / 10
                for _ in range(10):
                    self.v += h * (self.b * (ua - 5.0) - self.c * self.v + self.d(t))
                    self.y += h * self.v
        return out


def _params(axis, **updates):
    return with_updates(load_controller_params(axis), updates)


# -- the laws, on an ideal double integrator with b0 known ------------------


@pytest.mark.parametrize("lam", [20.0, 50.0])
def test_ladrc_is_critically_damped_at_lambda_1(lam):
    p = _params(
        "linear",
        algorithm="ladrc",
        **{"ladrc.lambda_1": lam, "ladrc.omega_0": 100.0, "td.enabled": False},
        **{"reference.kind": "constant", "reference.value": 1.0, "transport_delay_samples": 0},
    )
    out = Plant("linear", b=p.ladrc.b_0 / 1000.0, delay=0).run(AxisController("linear", p), 400)
    t = np.arange(400) * T
    expected = 1e-3 * (1 - (1 + lam * t) * np.exp(-lam * t))  # y/r = λ²/(s + λ)²
    assert np.abs(out["y"] - expected).max() < 0.012e-3
    assert out["y"].max() <= 1e-3 * (1 + 1e-6)  # no overshoot
    np.testing.assert_allclose(out["z3"], 0.0, atol=1e-9)  # nothing to estimate


@pytest.mark.parametrize("lam", [20.0, 50.0])
def test_sliding_surface_has_a_double_pole_at_minus_lambda(lam):
    """ε → 0: ṡ = 0, so e obeys ë + 2λė + λ²e = 0: e = e0 (1 + λt) e^{−λt}."""
    p = _params(
        "linear",
        algorithm="eso_smc",
        **{
            "eso_smc.lambda_r": lam,
            "eso_smc.epsilon": 1e-6,
            "eso_smc.delta": 1.0,
            "eso_smc.k": 1.0,
        },
        **{"td.enabled": False, "reference.kind": "constant", "reference.value": 0.0},
        transport_delay_samples=0,
    )
    e0 = 1e-3
    n = int(10 / lam / T)
    out = Plant("linear", b=p.eso_smc.b_0 / 1000.0, delay=0, y0=-e0).run(
        AxisController("linear", p), n
    )
    t = np.arange(n) * T
    assert np.abs(out["error"] - e0 * (1 + lam * t) * np.exp(-lam * t)).max() < 0.011 * e0
    assert np.all(out["error"] >= 0.0)  # no overshoot: a double real pole


def test_reaching_law_and_surface_together_match_continuous_solution():
    """ε > 0 inside a continuous layer: ṡ = −εk s and ë + 2λė + λ²e = ṡ (RK4 reference)."""
    lam, kappa, delta = 30.0, 20.0, 200.0  # s0 = 2λ e0 = 60 mm/s stays inside Δ
    p = _params(
        "linear",
        algorithm="eso_smc",
        **{"eso_smc.lambda_r": lam, "eso_smc.epsilon": kappa * delta, "eso_smc.delta": delta},
        **{"eso_smc.k": 1.0 / delta, "td.enabled": False, "reference.kind": "constant"},
        **{"reference.value": 0.0, "transport_delay_samples": 0},
    )
    e0 = 1.0  # mm
    n = 400
    out = Plant("linear", b=p.eso_smc.b_0 / 1000.0, delay=0, y0=-e0 * 1e-3).run(
        AxisController("linear", p), n
    )

    def f(x):  # x = (e, ė, s) in mm units
        e, ed, s = x
        sd = -kappa * s
        return np.array([ed, sd - 2 * lam * ed - lam * lam * e, sd])

    x, ref, h = np.array([e0, 0.0, 2 * lam * e0]), [], T / 20
    for _ in range(n):
        ref.append(x[0])
        for _ in range(20):
            k1 = f(x)
            k2 = f(x + h / 2 * k1)
            k3 = f(x + h / 2 * k2)
            k4 = f(x + h * k3)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    np.testing.assert_allclose(out["error"] * 1e3, ref, atol=0.01 * e0)
    assert out["s"][0] * 1e3 == pytest.approx(2 * lam * e0)  # s = ė + 2λe + λ²∫e at t = 0
    assert abs(out["s"][-1]) < 1e-3 * abs(out["s"][0])


@pytest.mark.parametrize("algorithm", ["ladrc", "eso_smc"])
def test_unknown_disturbance_and_b_error_rejected(algorithm):
    """Sine 20 mm 0.25 Hz, b 30 % above b0, viscous friction, a force step: e → small."""
    p = _params(
        "linear",
        algorithm=algorithm,
        **{"ladrc.lambda_1": 60.0, "ladrc.omega_0": 150.0, "eso_smc.lambda_r": 60.0},
        **{"eso_smc.omega_0": 150.0, "eso_smc.delta": 2.4, "eso_smc.k": 1 / 2.4},
    )
    b0 = (p.ladrc.b_0 if algorithm == "ladrc" else p.eso_smc.b_0) / 1000.0
    plant = Plant("linear", b=1.3 * b0, c=30.0, d=lambda t: -3.0 if t > 2.0 else 0.0)
    out = plant.run(AxisController("linear", p), 5000)
    e = np.abs(out["error"][3000:]) * 1e3
    assert e.max() < 0.1  # mm, after the step's transient
    assert np.abs(np.diff(out["u"][3000:])).max() < 0.05  # no chattering with k = 1/Δ


def test_paper_eso_smc_gains_limit_cycle_with_one_sample_delay():
    """Documented finding: λ_R = 250 with the 1-sample transport delay chatters; without it, not."""
    res = {}
    for delay in (0, 1):
        p = _params(
            "linear",
            algorithm="eso_smc",
            transport_delay_samples=delay,
            **{"reference.kind": "constant", "reference.value": 5.0},
        )
        out = Plant("linear", b=3.0, c=30.0, delay=delay).run(AxisController("linear", p), 3000)
        res[delay] = np.abs(np.diff(out["u"][2000:])).max()
    assert res[0] < 1e-6 and res[1] > 0.5


@pytest.mark.parametrize("algorithm", ["eso_smc", "ladrc"])
@pytest.mark.parametrize("delay", [1, 2])
def test_delay_compensation_removes_limit_cycle(algorithm, delay):
    """Paper gains, transport delay d: the predictor on the ESO model settles the step cleanly."""
    du = {}
    for dc in (False, True):
        p = _params(
            "linear",
            algorithm=algorithm,
            transport_delay_samples=delay,
            **{
                "reference.kind": "constant",
                "reference.value": 5.0,
                f"{algorithm}.delay_compensation": dc,
            },
        )
        out = Plant("linear", b=3.0, c=30.0, delay=delay).run(AxisController("linear", p), 3000)
        du[dc] = np.abs(np.diff(out["u"][2000:])).max()
        if dc:
            assert np.abs(out["error"][2000:]).max() < 1e-9  # m
    assert du[True] < 1e-6
    if (algorithm, delay) != ("ladrc", 1):  # LADRC at d = 1 is (just) stable uncompensated
        assert du[False] > 0.5


# -- bumpless switching -------------------------------------------------------

SMOOTH = {
    "ladrc.lambda_1": 60.0,
    "ladrc.omega_0": 150.0,
    "eso_smc.lambda_r": 60.0,
    "eso_smc.omega_0": 150.0,
    "eso_smc.delta": 2.4,
    "eso_smc.k": 1 / 2.4,
}


@pytest.mark.parametrize("gains", ["paper", "smooth"])
def test_bumpless_switching_mid_run(gains):
    base = _params("linear", **(SMOOTH if gains == "smooth" else {}))
    seq = {1500: "ladrc", 2500: "eso_smc", 3500: "pid", 4500: "eso_smc", 5500: "ladrc", 6500: "pid"}
    offsets = {}

    def hook(k, c):
        if k in seq:
            c.set_params(with_updates(base, {"algorithm": seq[k]}))
        if k - 1 in seq:
            offsets[k - 1] = c.bumpless_offset
            assert c.algorithm == seq[k - 1]

    ctrl = AxisController("linear", with_updates(base, {"algorithm": "pid"}))
    plant = Plant("linear", b=3.0, c=30.0, d=lambda t: -2.0 if t > 0.7 else 0.0)
    out = plant.run(ctrl, 7500, hook)
    u, e = out["u"], np.abs(out["error"]) * 1e3
    for k in seq:
        assert abs(u[k] - u[k - 1]) < 0.05, k  # the switching sample itself
        assert e[k : k + 300].max() < 0.2, k  # and the tracking is not upset
        if gains == "smooth":  # no hidden bump in the samples that follow
            assert np.abs(np.diff(u[k - 1 : k + 50])).max() < 0.1, k
    # the blend was needed: the new algorithms' own first commands differed
    assert max(abs(v) for v in offsets.values()) > 0.05


def test_parameter_change_within_algorithm_is_bumpless():
    base = _params("linear", algorithm="eso_smc", **SMOOTH)

    def hook(k, c):
        if k == 2000:
            c.set_params(with_updates(base, {"eso_smc.lambda_r": 90.0, "eso_smc.b_0": 2500.0}))

    out = Plant("linear", b=3.0, c=30.0).run(AxisController("linear", base), 3000, hook)
    assert abs(out["u"][2000] - out["u"][1999]) < 1e-9
    assert np.abs(np.diff(out["u"][1999:2050])).max() < 0.05


# -- saturation and anti-windup ---------------------------------------------


def _blocked_run(algorithm, n=4000, **updates):
    p = _params(
        "linear",
        algorithm=algorithm,
        **{"reference.kind": "constant", "reference.value": 5.0},
        **updates,
    )
    plant = Plant("linear", b=3.0, c=30.0, blocked=lambda t: t < 1.0)
    return plant.run(AxisController("linear", p), n)


def test_saturation_limits_and_pid_anti_windup_after_blocked_axis():
    runs = {
        aw: _blocked_run("pid", **{"pid.anti_windup": aw})
        for aw in ("conditional", "back_calculation", "none")
    }
    for out in runs.values():
        assert out["u"].min() >= 0.0 and out["u"].max() <= 10.0
        assert out["u"][500] == 10.0 and out["u_raw"][500] > 10.0  # saturated while blocked
    over = {aw: (out["y"][1000:].max() - 5e-3) * 1e3 for aw, out in runs.items()}
    assert over["none"] > 20.0  # the wound-up integral (≈ 23 V) throws the piston far past
    assert over["conditional"] < 0.3 * over["none"]
    assert over["back_calculation"] < 0.3 * over["none"]
    for aw in ("conditional", "back_calculation"):
        assert abs(runs[aw]["error"][-1]) < 1e-6


def test_eso_smc_integral_anti_windup_after_blocked_axis():
    # no transport delay here so that the paper's gains settle without a limit cycle
    kw = {"transport_delay_samples": 0}
    on = _blocked_run("eso_smc", 6000, **kw)
    off = _blocked_run("eso_smc", 6000, **kw, **{"eso_smc.integral_anti_windup": False})
    eps_over_lam2 = 1200.0 / 250.0**2  # mm: the offset a wound-up s leaves
    assert np.abs(off["error"][4000:] * 1e3).min() > 0.9 * eps_over_lam2
    assert np.abs(on["error"][4000:] * 1e3).max() < 1e-4
    assert on["u"].min() >= 0.0 and on["u"].max() <= 10.0


def test_custom_limits_respected():
    p = _params(
        "linear",
        algorithm="ladrc",
        **{"limits.u_min": 2.0, "limits.u_max": 7.0, "limits.u_neutral": 4.5},
    )
    out = Plant("linear", b=3.0, c=30.0, blocked=lambda t: t < 0.5).run(
        AxisController("linear", p), 1500
    )
    assert out["u"].min() >= 2.0 and out["u"].max() <= 7.0
    assert (out["u"] == 7.0).any() or (out["u"] == 2.0).any()


# -- rotary axis: speed loop and friction compensation ----------------------


def _rotary_plant_run(p, n, fric_c=None):
    """ω̇ = a − c ω (viscous, c = M_v κ/J... in SI), ȧ = b u: speed is 2nd order in u."""
    b = p.eso_smc.b_0 / RPM  # rad/s³ per V
    c = fric_c if fric_c is not None else RPM * p.eso_smc.M_v / p.eso_smc.J_m
    ctrl = AxisController("rotary", p)
    w = a = 0.0
    q = [5.0]
    z3, err, us = [], [], []
    for k in range(n):
        u = ctrl.update(SensorSample(k, k * 1_000_000, 2e5, 2e5, 2e5, 0.0, 0.0, w, 0))
        st = ctrl.state
        z3.append(st.z3)
        err.append(st.error)
        us.append(u)
        q.append(u)
        ua = q.pop(0)
        for _ in range(10):
            h = T / 10
            a += h * b * (ua - 5.0)
            w += h * (a - c * w)
    return np.array(z3), np.array(err), np.array(us)


def test_rotary_friction_compensation_sign_and_units():
    """With M_v/J_m known, z3 is left with (almost) nothing to estimate on a speed ramp."""
    base = {
        "algorithm": "eso_smc",
        "eso_smc.delta": 2.0,
        "eso_smc.k": 0.5,
        "eso_smc.lambda_r": 40.0,
        "eso_smc.omega_0": 40.0,
        "eso_smc.M_c": 0.0,
        "reference.kind": "ramp",
        "reference.offset": 0.0,
        "reference.slope": 50.0,
    }
    z3_on, e_on, _ = _rotary_plant_run(_params("rotary", **base), 3000)
    z3_off, e_off, _ = _rotary_plant_run(
        _params("rotary", **base, **{"eso_smc.friction_compensation": False}), 3000
    )
    # viscous friction in the speed loop's jerk model: −(M_v/J) ω̇ = −23.6·50 rpm/s² on the ramp
    c = RPM * 8.66e-5 / 3.5e-5
    assert z3_off[-1] * RPM == pytest.approx(-c * 50.0, rel=0.05)
    assert abs(z3_on[-1] * RPM) < 0.02 * c * 50.0
    assert abs(e_on[-1]) * RPM < 0.5 and abs(e_off[-1]) * RPM < 0.5


def test_rotary_paper_gains_reach_800_rpm_on_speed_model():
    """Paper rotary ESO-SMC gains, speed loop, b = b0, weak damping, compensation off."""
    p = _params("rotary", algorithm="eso_smc", **{"eso_smc.friction_compensation": False})
    _, err, u = _rotary_plant_run(p, 8000, fric_c=1.0)
    assert np.abs(err[-1000:]).max() * RPM < 2.0  # rpm, the paper's ±2 rpm band
    assert u.min() >= 0.0 and u.max() <= 10.0


def test_rotary_friction_compensation_with_wrong_model_is_destabilising():
    """Documented risk: compensating M_v/J_m = 23.6 1/s on a plant with 1 1/s is anti-damping."""
    p = _params("rotary", algorithm="eso_smc")
    _, err, _ = _rotary_plant_run(p, 8000, fric_c=1.0)
    assert np.abs(err[-1000:]).max() * RPM > 20.0


# -- determinism, non-finite input, state -----------------------------------


def test_deterministic_and_reset_repeats_bitwise():
    p = _params("linear", algorithm="eso_smc")
    ctrl = AxisController("linear", p)
    a = Plant("linear", b=3.0, c=30.0).run(ctrl, 1500)
    b = Plant("linear", b=3.0, c=30.0).run(AxisController("linear", p), 1500)
    ctrl.reset()
    c = Plant("linear", b=3.0, c=30.0).run(ctrl, 1500)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name])
        np.testing.assert_array_equal(a[name], c[name])


def test_nonfinite_measurement_holds_command_and_states():
    ctrl = AxisController("linear", _params("linear", algorithm="ladrc"))
    for k in range(100):
        u = ctrl.update(SensorSample(k, k * 1_000_000, 2e5, 2e5, 2e5, 1e-4 * k, 0.0, 0.0, 0))
    z = (ctrl.state.z1, ctrl.state.z2, ctrl.state.z3)
    assert ctrl.update(SensorSample(100, 100_000_000, 2e5, 2e5, 2e5, math.nan, 0.0, 0.0, 0)) == u
    assert ctrl.n_nonfinite == 1 and (ctrl.state.z1, ctrl.state.z2, ctrl.state.z3) == z
    assert math.isfinite(
        ctrl.update(SensorSample(101, 101_000_000, 2e5, 2e5, 2e5, 1e-2, 0.0, 0.0, 0))
    )


def test_state_fields_and_units():
    assert STATE_FIELDS == tuple(f for f in ControllerState.__slots__ if f != "algorithm")
    ctrl = AxisController("rotary", _params("rotary", algorithm="pid"))
    ctrl.update(SensorSample(0, 5_000_000_000, 2e5, 2e5, 2e5, 0.0, 0.0, 10.0, 0))
    st = ctrl.state
    assert st.t == 0.0 and st.algorithm == "pid"
    assert st.reference == pytest.approx(800.0 / RPM) and st.measured == 10.0
    assert st.error == pytest.approx(800.0 / RPM - 10.0)
    assert math.isnan(st.z1) and math.isnan(st.s)
    assert ctrl.state_values() == tuple(getattr(st, f) for f in STATE_FIELDS)
    ctrl.update(SensorSample(1, 5_001_000_000, 2e5, 2e5, 2e5, 0.0, 0.0, 10.0, 0))
    assert ctrl.state.t == pytest.approx(0.001)


# -- rotary angle reading (rotary_model: angle) -----------------------------


def _angle_plant_run(p, n, hook=None):
    """θ̈ = b0 (u − 5) with b0 in rpm/s/V (the angle reading of Eq. 25), one-sample delay."""
    b = p.eso_smc.b_0 / RPM  # rad/s² per V
    ctrl = AxisController("rotary", p)
    th = w = 0.0
    q = [5.0]
    err, us = [], []
    for k in range(n):
        if hook:
            hook(k, ctrl)
        u = ctrl.update(SensorSample(k, k * 1_000_000, 2e5, 2e5, 2e5, 0.0, th, w, 0))
        err.append(ctrl.state.error)
        us.append(u)
        q.append(u)
        a = b * (q.pop(0) - 5.0)
        th += T * w + 0.5 * T * T * a
        w += T * a
    return np.array(err) * RPM, np.array(us)


@pytest.mark.parametrize("algorithm", ["eso_smc", "ladrc", "pid"])
def test_rotary_angle_model_reaches_800_rpm(algorithm):
    p = _params(
        "rotary",
        algorithm=algorithm,
        rotary_model="angle",
        **{"eso_smc.friction_compensation": False},
    )
    err, u = _angle_plant_run(p, 6000)
    assert np.abs(err[4000:]).max() < 2.0  # rpm
    assert u.min() >= 0.0 and u.max() <= 10.0


def test_rotary_angle_model_switching_is_bumpless():
    base = _params("rotary", rotary_model="angle", **{"eso_smc.friction_compensation": False})
    seq = {2000: "ladrc", 3000: "pid", 4000: "eso_smc", 5000: "pid", 6000: "ladrc"}

    def hook(k, c):
        if k in seq:
            c.set_params(with_updates(base, {"algorithm": seq[k]}))

    err, u = _angle_plant_run(with_updates(base, {"algorithm": "eso_smc"}), 7000, hook)
    for k in seq:
        assert abs(u[k] - u[k - 1]) < 0.05, k
        assert np.abs(err[k : k + 500]).max() < 5.0, k  # rpm
    with pytest.raises(Exception, match="rotary_model"):
        AxisController("rotary", base).set_params(with_updates(base, {"rotary_model": "speed"}))
