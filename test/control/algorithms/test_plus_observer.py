"""ESO-SMC+ pieces: the integrator-chain ESO, the valve-curve map, the law, the parameters."""

import math

import numpy as np
import pytest
from pneu_control.algorithms.base import StepInput
from pneu_control.algorithms.eso_smc_plus import EsoSmcPlus, ValveCurve
from pneu_control.controller.params import load_controller_params
from pneu_control.observers.eso import eso_gains
from pneu_control.observers.eso_chain import ChainEso, chain_gains, chain_matrices
from pneu_msgs_py.contract.valve_chart import MPYE_DU_V, MPYE_FLOW
from pneu_msgs_py.params.core import ParamError, with_updates

T = 0.001


@pytest.mark.parametrize("w0", [10.0, 51.4, 300.0, 3000.0])
def test_chain_gains_n3_equal_the_papers_eso(w0):
    assert chain_gains(3, w0, T) == pytest.approx(eso_gains(w0, T), rel=1e-9)


@pytest.mark.parametrize("n, w0", [(2, 40.0), (4, 120.0), (4, 30.0), (5, 200.0)])
def test_chain_error_matrix_has_all_poles_at_exp_minus_w0_T(n, w0):
    phi, _ = chain_matrices(n, T)
    L = np.array(chain_gains(n, w0, T))
    c = np.zeros(n)
    c[0] = 1.0
    a = (np.eye(n) - np.outer(L, c)) @ phi
    p = math.exp(-w0 * T)
    # characteristic polynomial (z − p)^n (eigenvalues of a repeated pole are ill-conditioned)
    assert np.poly(a) == pytest.approx(np.poly(np.full(n, p)), abs=1e-9)


def test_chain_eso_converges_on_exact_zoh_plant_with_constant_disturbance():
    b0, f, w0 = 2.3e6, -4.0e6, 120.0
    eso = ChainEso(4, w0, b0, T)
    phi, gam = chain_matrices(4, T)
    x = np.array([0.0, 800.0, 0.0, f])  # θ (rpm·s), ω (rpm), ω̇, f
    eso.reset(0.0, 0.0)
    rng = np.random.default_rng(1)
    for _k in range(3000):
        u = 1.7 + 0.1 * rng.standard_normal()
        x = phi @ x + gam * b0 * u
        eso.update(x[0], u)
    assert eso.z == pytest.approx(x, rel=1e-6, abs=1e-6)


def _rotary(**upd):
    base = {"algorithm": "eso_smc_plus", "eso_smc_plus.delay_compensation": False, **upd}
    return with_updates(load_controller_params("rotary"), base)


def test_inlined_angle_observer_matches_the_slow_reference():
    params = _rotary()
    alg = EsoSmcPlus(params, "rotary")
    p = params.eso_smc_plus
    ref = ChainEso(4, p.omega_0, p.b_0, T)
    rng = np.random.default_rng(7)
    alg.start(StepInput(y=0.0, r=800.0, theta=0.0), None, (math.nan,) * 3)
    ref.reset(0.0, 0.0)
    u = 0.0
    for k in range(1, 2000):
        th = 800.0 * k * T + 0.2 * math.sin(0.3 * k) + 0.05 * rng.standard_normal()
        u_next = alg.update(StepInput(y=800.0, r=800.0, u_applied=u, theta=th))
        ref.update(th, u)
        assert (alg.z1, alg.z2, alg.z3, alg.z4) == pytest.approx(tuple(ref.z), rel=1e-9, abs=1e-7)
        u = u_next


def test_surface_integral_is_the_measured_angle_error():
    """s = ë + 2λė + λ²e with e = θ_r − θ̂: with an exact observer, s is set by the angle."""
    params = _rotary(**{"eso_smc_plus.lambda_r": 30.0})
    alg = EsoSmcPlus(params, "rotary")
    alg.start(StepInput(y=800.0, r=800.0, theta=0.0), None, (math.nan,) * 3)
    # the motor lags the reference by exactly 10 rpm·s of angle at the reference speed
    alg.st.z1, alg.st.z2, alg.st.z3, alg.st.z4 = -10.0, 800.0, 0.0, 0.0
    # exactly the prediction: no innovation
    alg.update(StepInput(y=800.0, r=800.0, theta=-10.0 + 800.0 * T))
    assert alg.s == pytest.approx(30.0**2 * 10.0, rel=1e-3)


def test_valve_curve_is_a_bijection_through_the_unit_point():
    vc = ValveCurve(MPYE_DU_V, MPYE_FLOW, 1.0)
    assert vc.to_valve(1.0) == pytest.approx(1.0, abs=1e-12)
    assert vc.to_valve(-1.0) == pytest.approx(-1.0, abs=1e-12)
    for u in np.linspace(-5.0, 5.0, 2001):
        assert vc.to_valve(vc.to_linear(u)) == pytest.approx(u, abs=1e-12)
    v = np.linspace(-20.0, 20.0, 4001)
    u = np.array([vc.to_valve(x) for x in v])
    assert np.all(np.diff(u) > 0.0)  # strictly increasing
    # the flat start of the chart (dead band) is opened quickly: small v -> larger u
    assert vc.to_valve(0.1) > 0.2


def test_params_refuse_bad_tables_and_boundary_layer():
    base = load_controller_params("linear")
    with pytest.raises(ParamError, match="valve_flow_table"):
        with_updates(base, {"eso_smc_plus.valve_flow_table": (0.0, 0.5, 0.4, 1.0)})
    with pytest.raises(ParamError, match="eso_smc_plus.k"):
        with_updates(base, {"eso_smc_plus.k": 2.0 / base.eso_smc_plus.delta})
    with pytest.raises(ParamError, match="eso_smc_plus.omega_0"):
        with_updates(base, {"eso_smc_plus.omega_0": 4000.0})
