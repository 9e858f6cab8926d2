"""ESO-SMC+ on the linear axis with the measured chamber pressures (linear_model force,
friction_feedforward): the pressure force as a measurement, the Eq. 2 feed-forward, closed loop.
"""

import math

import numpy as np
import pytest
from pneu_control.algorithms import StepInput, make_algorithm
from pneu_control.controller.axis import AxisController
from pneu_control.controller.params import load_controller_params
from pneu_msgs_py.contract.units import MM_PER_M
from pneu_msgs_py.params.core import ParamError, with_updates
from pneu_msgs_py.params.paths import config_file
from pneu_sim.physics.plant import Plant
from pneu_sim.physics.plant_file import load_plant

RETUNED = config_file("controllers_retuned.yaml")
DEFAULTS = config_file("controllers.yaml")
SINE = {"reference.kind": "sine", "reference.amplitude": 20.0, "reference.frequency_hz": 0.25}
FORCE = {
    "eso_smc_plus.linear_model": "force",
    "eso_smc_plus.valve_linearisation": True,
    "eso_smc_plus.lambda_r": 120.0,
    "eso_smc_plus.omega_0": 60.0,
}


def _plus(overrides):
    p = load_controller_params("linear", DEFAULTS, {"algorithm": "eso_smc_plus", **overrides})
    return p, make_algorithm(p, "linear")


def test_pressure_force_is_eq1_with_the_rod_at_ambient():
    _, alg = _plus({"eso_smc_plus.linear_model": "force"})
    assert alg.uses_pressures
    A1, A2, p_a = 8.04e-4, 6.912e-4, 101325.0
    inp = StepInput(p_c1=3.0e5, p_c2=2.0e5)
    assert alg._pressure_force(inp) == pytest.approx(A1 * 3.0e5 - A2 * 2.0e5 - (A1 - A2) * p_a)
    # balanced chambers at ambient: no force
    assert alg._pressure_force(StepInput(p_c1=p_a, p_c2=p_a)) == pytest.approx(0.0, abs=1e-9)


def test_position_model_does_not_ask_for_pressures():
    _, alg = _plus({})
    assert not alg.uses_pressures


def test_pressure_aided_velocity_estimate_beats_the_laser_only_eso():
    # the same closed-loop run (ESO-SMC drives the twin); two ESO-SMC+ observers read it
    plant_p = load_plant(None)
    plant = Plant(plant_p, seed=3)
    s = plant.reset()
    drive = AxisController(
        "linear", with_updates(load_controller_params("linear", RETUNED), {**SINE})
    )
    _, laser = _plus({"eso_smc_plus.omega_0": 60.0})
    _, force = _plus({**FORCE})
    u_hold = 5.0
    err_l, err_f = [], []
    for k in range(3000):
        u = drive.update(s)
        y = s.x * MM_PER_M
        if k == 0:
            for a in (laser, force):
                a.start(StepInput(y=y, p_c1=s.p_c1, p_c2=s.p_c2), None, (math.nan,) * 3)
        else:
            inp = StepInput(y=y, u_applied=u_hold - 5.0, p_c1=s.p_c1, p_c2=s.p_c2)
            for a in (laser, force):
                a.update(inp)
        if k > 500:
            v = plant.state.v * MM_PER_M
            err_l.append(laser.z2 - v)
            err_f.append(force.z2 - v)
        s = plant.step(u_hold, 5.0)
        u_hold = u
    rms_l = float(np.sqrt(np.mean(np.square(err_l))))
    rms_f = float(np.sqrt(np.mean(np.square(err_f))))
    assert rms_f < 0.7 * rms_l, (rms_f, rms_l)


def test_friction_feedforward_delivers_the_eq2_force_change_over_a_reversal():
    p, alg = _plus({"eso_smc_plus.friction_feedforward": True})
    T, q = p.sample_time_s, p.eso_smc_plus
    w = 2.0 * math.pi * 0.25
    alg.start(StepInput(y=20.0, r=20.0, r_ddot=-20.0 * w * w), None, (math.nan,) * 3)
    total = 0.0
    r_dot0 = r_dot = None
    for k in range(1, 1001):  # 1 s across the top reversal of the 20 mm, 0.25 Hz sine
        t = k * T - 0.5
        r, r_dot, r_ddot = (
            20 * math.cos(w * t),
            -20 * w * math.sin(w * t),
            -20 * w * w * math.cos(w * t),
        )
        if r_dot0 is None:
            r_dot0 = r_dot
        alg.update(StepInput(y=r, r=r, r_dot=r_dot, r_ddot=r_ddot))
        total += alg.u_ff * T * q.b_F  # N
    F_f = lambda v: q.A_f * math.tanh(v / q.v_s) + q.c_v * 1e-3 * v  # noqa: E731 (Eq. 2)
    assert total == pytest.approx(F_f(r_dot) - F_f(r_dot0), rel=1e-9)
    assert total < -1.9 * q.A_f  # the force reverses by about 2 A_f


def _run(algorithm_params, seconds, seed=0, switch_at=None, switch_to=None):
    plant = Plant(load_plant(None), seed=seed)
    s = plant.reset()
    c = AxisController("linear", algorithm_params)
    u_hold, us, errs = 5.0, [], []
    for k in range(int(seconds * 1000)):
        if switch_at is not None and k == switch_at:
            c.set_params(switch_to)
        u = c.update(s)
        us.append(u)
        if k > 2000:
            errs.append(c.state.reference - plant.state.x)
        s = plant.step(u_hold, 5.0)
        u_hold = u
    return np.array(us), np.array(errs) * MM_PER_M


def test_force_cascade_tracks_the_sine_without_a_limit_cycle():
    p, _ = _plus({**SINE, **FORCE})
    us, errs = _run(p, 6.0, seed=1)
    assert np.abs(errs).max() < 1.5  # mm (true error; ESO-SMC ≈ 0.45 here)
    assert np.mean((us <= 0.01) | (us >= 9.99)) < 0.01  # no bang-bang chatter


@pytest.mark.parametrize("overrides", [FORCE, {"eso_smc_plus.friction_feedforward": True}])
def test_switching_from_eso_smc_to_the_pressure_variants_is_bumpless(overrides):
    base = with_updates(load_controller_params("linear", RETUNED), {**SINE})
    plus, _ = _plus({**SINE, **overrides})
    us, errs = _run(base, 4.0, switch_at=3000, switch_to=plus)
    assert abs(us[3000] - us[2999]) < 0.05  # V: the first command equals the last one
    assert np.abs(errs).max() < 2.0


def test_bad_geometry_is_refused():
    with pytest.raises(ParamError, match="A_c2"):
        _plus({"eso_smc_plus.A_c2": 9e-4})


def test_a_nan_pressure_sample_holds_the_last_force():
    _, alg = _plus({**SINE, **FORCE})
    alg.start(StepInput(p_c1=2.0e5, p_c2=2.0e5), None, (math.nan,) * 3)
    u1 = alg.update(StepInput(r=0.1, p_c1=2.0e5, p_c2=2.0e5))
    u2 = alg.update(StepInput(r=0.1, u_applied=u1, p_c1=math.nan, p_c2=2.0e5))
    assert math.isfinite(u2)
    assert alg.F_p == pytest.approx((8.04e-4 - 6.912e-4) * (2.0e5 - 101325.0))  # the last valid
