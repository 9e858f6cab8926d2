"""Coupling of the axes, external loads and the bidirectional motor plumbing.

The paper-only twin is the reference: with coupling and loads off and the paper's
plumbing, the kernel must give bit for bit what the kernel of the commit before
these terms gave (its source is read from git history and compiled here; the
catalogue valve curve packed in its layout).
"""

import importlib.util
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest
from pneu_msgs_py.contract.units import RPM_PER_RAD_S
from pneu_msgs_py.params.core import ParamError, with_updates
from pneu_sim.physics import kernel as k
from pneu_sim.physics.params import K_SEAL_ESTIMATE, PlantParams
from pneu_sim.physics.plant import Plant

# the last commit whose kernel had no coupling, loads or second plumbing
PAPER_ONLY_COMMIT = "897da2952ff4b94131b6c41e751453059b57a03b"
KERNEL_PATH = "src/pneu_sim/pneu_sim/physics/kernel.py"
ROOT = Path(__file__).resolve().parents[3]

UNCOUPLED = {"coupling.k_seal": 0.0, "coupling.mu_sleeve": 0.0}
SEALED = {"valve_linear.leak_fraction": 0.0, "valve_rotary.leak_fraction": 0.0}
SEALS = {"coupling.k_seal": K_SEAL_ESTIMATE}  # the seal torque as estimated (nominal: off)


def plant_with(updates, seed=0):
    return Plant(with_updates(PlantParams(), updates), seed=seed)


def run_for(plant, seconds, u_l=5.0, u_r=5.0):
    for _ in range(round(seconds / plant.T)):
        plant.step(u_l, u_r)
    return plant.state


def _old_kernel(tmp_path):
    try:
        src = subprocess.run(
            ["git", "show", f"{PAPER_ONLY_COMMIT}:{KERNEL_PATH}"],
            cwd=ROOT,
            capture_output=True,
            check=True,
            text=True,
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip(f"git history with {PAPER_ONLY_COMMIT[:10]} not available")
    path = tmp_path / "kernel_paper_only.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location("kernel_paper_only", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _old_layout(old, prm, params):
    """``prm`` in the paper-only kernel's layout: the same values before the valve blocks,
    each valve's opening curve as that kernel's |u - 5 V| table (the valves' blocks have
    since become a signed curve per port, pneu_sim.physics.valve_curve)."""
    out = np.zeros(old.P_VALVE_R + old.VB_SIZE)
    out[: old.P_VALVE_L] = prm[: k.P_VALVE_L]
    for ob, nb, v in (
        (old.P_VALVE_L, k.P_VALVE_L, params.valve_linear),
        (old.P_VALVE_R, k.P_VALVE_R, params.valve_rotary),
    ):
        out[ob : ob + old.VB_TAB] = prm[nb : nb + k.VB_TAB4]
        out[ob + old.VB_DULAP] = v.du_table[1]
        du = np.arange(old.TAB_N) * old.TAB_DU
        out[ob + old.VB_TAB : ob + old.VB_SIZE] = np.interp(du, v.du_table, v.flow_table)
    return out


def test_off_is_bit_identical_to_the_paper_only_kernel(tmp_path):
    old = _old_kernel(tmp_path)
    assert old.N_STATE <= k.N_STATE and old.P_VALVE_L == k.P_VALVE_L  # layout appended to
    plant = plant_with(UNCOUPLED, seed=3)
    plant.reset(x0=0.01, omega0=300 / RPM_PER_RAD_S)
    st, prm, _ = plant.kernel_arrays()
    prm_old = _old_layout(old, prm, plant.params)
    rng = np.random.default_rng(7)
    n = 3000  # both axes driven hard: end stop, reversals, motor up and down
    u_l = np.clip(5.0 + 3.0 * np.sin(np.arange(n) * 2e-3) + rng.normal(0, 0.5, n), 0, 10)
    u_r = np.clip(6.5 + 3.0 * np.sin(np.arange(n) * 3e-3) + rng.normal(0, 0.5, n), 0, 10)
    noise = plant.noise_rows(n)
    st_old = st.copy()
    out_new = np.empty((n, k.N_OUT))
    out_old = np.empty((n, old.N_OUT))
    k.run_periods(st, prm, noise, u_l, u_r, out_new)
    old.run_periods(st_old, prm_old, noise, u_l, u_r, out_old)
    assert np.array_equal(out_new, out_old)
    # the unobserved states (exhaust pressure, gas-mass bookkeeping) to the last bits: the
    # compiler orders the valve-area arithmetic of the per-port curves differently
    np.testing.assert_allclose(st[: old.N_STATE], st_old[: old.N_STATE], rtol=1e-12, atol=0.0)
    assert np.ptp(out_new[:, k.O_X]) > 0.05 and np.ptp(out_new[:, k.O_OM]) > 50  # it moved


# ------------------------------------------------------------------ external loads
@pytest.mark.parametrize("F_ext", [40.0, -40.0])
def test_constant_force_shifts_the_pressure_force_by_F_ext(F_ext):
    # sealed valve at 5 V: the piston moves until the chambers' force balances F_ext
    # within the breakaway friction
    plant = plant_with({**SEALED, "load.F_ext": F_ext})
    plant.reset()
    lin = plant.params.linear
    p_a = plant.params.ambient.p_a
    s0 = plant.state
    F_p0 = lin.A_c1 * s0.p_c1 - lin.A_c2 * s0.p_c2 - lin.A_r * p_a
    assert F_p0 == pytest.approx(-F_ext, abs=1e-9)  # reset balances the load
    plant.set_load(F_ext=0.0)
    s = run_for(plant, 0.5)  # the load removed: the chambers push back, the piston moves
    assert s.v == 0.0
    assert abs(s.x) > 1e-3
    F_p = lin.A_c1 * s.p_c1 - lin.A_c2 * s.p_c2 - lin.A_r * p_a
    F_s = lin.A_f * lin.breakaway_ratio
    assert abs(F_p) <= F_s + 1e-9  # at rest: what is left is held by friction
    plant.set_load(F_ext=F_ext)
    s = run_for(plant, 0.5)
    assert s.v == 0.0
    F_p = lin.A_c1 * s.p_c1 - lin.A_c2 * s.p_c2 - lin.A_r * p_a
    assert abs(F_p + F_ext) <= F_s + 1e-9
    assert math.copysign(1.0, s.p_c2 - s.p_c1) == math.copysign(1.0, F_ext)


def test_spring_pulls_the_piston_towards_its_relaxed_position():
    kk, x_0 = 4000.0, 0.03
    plant = plant_with({**SEALED, "load.k_spring": kk, "load.x_0": x_0})
    plant.reset(x0=0.0)  # reset balances the preload k x_0 with p_c2
    lin = plant.params.linear
    p_a = plant.params.ambient.p_a
    s = plant.state
    assert lin.A_c1 * s.p_c1 - lin.A_c2 * s.p_c2 - lin.A_r * p_a == pytest.approx(-kk * x_0)
    plant.set_state(p_c2=s.p_c1 * lin.A_c1 / lin.A_c2)  # drop the balance: spring wins
    s = run_for(plant, 1.0)
    assert s.v == 0.0 and 0.0 < s.x < x_0  # towards x_0, stopped by the compressed chamber 2
    F_p = lin.A_c1 * s.p_c1 - lin.A_c2 * s.p_c2 - lin.A_r * p_a
    assert abs(F_p - kk * (s.x - x_0)) <= lin.A_f * lin.breakaway_ratio + 1e-9


def test_load_breakaway_holds_below_and_turns_above():
    big = 5.0
    plant = plant_with({**SEALS, "load.T_bk": big})
    plant.reset()
    u_r = 6.5  # turns the unloaded motor at several hundred rpm
    s = run_for(plant, 1.0, u_r=u_r)
    assert s.omega == 0.0
    stall = k.vane_factor(plant.kernel_arrays()[1], s.theta) * (s.p_m1 - s.p_m2)
    rot, cp = plant.params.rotary, plant.params.coupling
    p_a = plant.params.ambient.p_a
    T_seal = cp.k_seal * (max(s.p_c1 - p_a, 0) + max(s.p_c2 - p_a, 0))
    hold = rot.M_c * rot.static_ratio + T_seal  # what the motor holds without the load
    assert 0.1 < stall - hold < big
    assert s.T_rod == pytest.approx(min(stall, T_seal + big))
    plant.set_load(T_bk=(stall - hold) * 1.05)  # just above the stall torque: still held
    s = run_for(plant, 0.3, u_r=u_r)
    assert s.omega == 0.0
    plant.set_load(T_bk=(stall - hold) * 0.95, T_c=(stall - hold) * 0.5)  # below: breaks away
    s = run_for(plant, 0.3, u_r=u_r)
    assert s.omega > 10.0


def test_load_torque_and_inertia_slow_the_motor():
    def speed_and_rise(**load):
        plant = plant_with({f"load.{n}": v for n, v in load.items()})
        plant.reset()
        w = []
        for _ in range(1500):
            plant.step(5.0, 7.0)
            w.append(plant.state.omega)
        w = np.array(w)
        return w[-200:].mean(), int(np.argmax(w > 0.5 * w[-200:].mean()))

    w0, t0 = speed_and_rise()
    w_c, _ = speed_and_rise(T_c=0.05)
    w_v, _ = speed_and_rise(c_load=2e-4)
    w_j, t_j = speed_and_rise(J_load=1e-4)
    assert w_c < w0 and w_v < w0
    assert w_j == pytest.approx(w0, rel=0.03)  # inertia: same speed, later
    assert t_j > 2 * t0


def test_set_load_refuses_bad_input_whole_and_keeps_old():
    plant = Plant(PlantParams())
    plant.set_load(T_c=0.1)
    with pytest.raises(ParamError, match="load.T_bx"):
        plant.set_load(T_bx=0.2)
    with pytest.raises(ParamError, match="load.T_c"):
        plant.set_load(T_bk=0.3, T_c=-1.0)
    assert plant.params.load.T_c == 0.1 and plant.params.load.T_bk == 0.0
    assert plant.kernel_arrays()[1][k.P_TLC] == 0.1


def test_set_load_mid_run_is_deterministic_and_reaches_the_compiled_arrays():
    def run(switch_at):
        plant = Plant(PlantParams(), seed=5)
        plant.reset()
        st, prm, out = plant.kernel_arrays()
        rows = []
        for i in range(600):
            if i == switch_at:
                plant.set_load(T_c=0.08, F_ext=-30.0)
            noise = plant.noise_rows(1)
            k.step_period(st, prm, noise, 0, 6.0, 7.0, out)  # as pneu_control.fastloop does
            rows.append(out.copy())
        return np.array(rows)

    a, b, c = run(300), run(300), run(10**9)
    assert np.array_equal(a, b)
    assert np.array_equal(a[:300], c[:300]) and not np.array_equal(a[300:], c[300:])


# ------------------------------------------------------------------ coupling
def test_seal_friction_torque_grows_with_chamber_pressure():
    def steady(p_c):
        plant = plant_with({**SEALED, **SEALS})
        plant.reset(x0=0.075)  # at the end stop: the pressures cannot move the piston
        plant.set_state(p_c1=p_c, p_c2=p_c)
        run_for(plant, 1.5, u_r=7.0)
        w, tq = [], []
        prm = plant.kernel_arrays()[1]
        for _ in range(500):
            plant.step(5.0, 7.0)
            s = plant.state
            w.append(s.omega)
            tq.append(k.vane_factor(prm, s.theta) * (s.p_m1 - s.p_m2))
        return np.mean(w), np.mean(tq), plant

    p_a = PlantParams().ambient.p_a
    w_lo, tq_lo, plant = steady(p_a)
    w_hi, tq_hi, _ = steady(p_a + 4e5)
    rot, cp = plant.params.rotary, plant.params.coupling
    assert w_hi < w_lo
    # Eq. 7 at constant speed: torque = M_c + T_seal + M_v ω, T_seal = k_seal Σ gauge
    for w, tq, gauge in ((w_lo, tq_lo, 0.0), (w_hi, tq_hi, 8e5)):
        assert tq == pytest.approx(rot.M_c + cp.k_seal * gauge + rot.M_v_si * w, rel=0.01)


def test_sleeve_friction_holds_the_piston_while_the_motor_passes_torque():
    # equal chamber pressures push the piston out with A_r (p - p_a) = 6 N > F_s = 4.4 N;
    # a load torque through the sleeve adds mu |T_rod| / r and holds it
    F_push = 6.0

    def moved(T_c):
        plant = plant_with({**SEALED, **SEALS, "load.T_c": T_c})
        plant.reset(omega0=600 / RPM_PER_RAD_S)
        lin = plant.params.linear
        p = plant.params.ambient.p_a + F_push / lin.A_r
        plant.set_state(p_c1=p, p_c2=p, v=0.0)
        x0 = plant.state.x
        s = run_for(plant, 0.2, u_r=8.0)
        assert s.omega > 100  # the motor keeps turning
        return abs(s.x - x0), s.T_rod, plant

    d_free, T_free, plant = moved(0.0)
    d_held, T_held, _ = moved(0.1)
    cp, lin = plant.params.coupling, plant.params.linear
    F_s = lin.A_f * lin.breakaway_ratio
    assert F_s + cp.mu_sleeve * T_free / cp.r_sleeve < F_push  # too little to hold
    assert F_s + cp.mu_sleeve * T_held / cp.r_sleeve > F_push
    assert d_free > 2e-4  # until the sealed chambers' stiffness takes up the excess
    assert d_held == 0.0


# ------------------------------------------------------------------ bidirectional plumbing
BIDIR = {"rotary.plumbing": "bidirectional"}


@pytest.mark.parametrize("u_r, sign", [(2.0, -1.0), (8.0, 1.0)])
def test_bidirectional_below_5V_reverses_above_drives_forward(u_r, sign):
    plant = plant_with(BIDIR)
    plant.reset()
    s = run_for(plant, 1.0, u_r=u_r)
    assert sign * s.omega * RPM_PER_RAD_S > 1000
    hi, lo = (s.p_m1, s.p_m2) if sign > 0 else (s.p_m2, s.p_m1)
    assert hi > lo  # the pressurised port is the one the valve feeds


def test_bidirectional_forward_and_reverse_speeds_are_alike():
    w = {}
    for u_r in (3.0, 7.0):
        plant = plant_with(BIDIR)
        plant.reset()
        w[u_r] = run_for(plant, 1.5, u_r=u_r).omega
    assert w[7.0] > 0 > w[3.0]
    assert -w[3.0] == pytest.approx(w[7.0], rel=0.15)  # V_m1 != V_m2: not exactly


def test_paper_plumbing_cannot_reverse():
    plant = Plant(PlantParams())
    plant.reset()
    s = run_for(plant, 1.0, u_r=2.0)
    assert s.omega == 0.0


def test_bidirectional_valve_at_5V_brakes_harder_than_the_paper_plumbing():
    def decel(updates):
        plant = plant_with(updates)
        plant.reset(omega0=800 / RPM_PER_RAD_S)
        w, dp = [], []
        for _ in range(400):
            w.append(plant.step(5.0, 5.0).omega)
            dp.append(plant.state.p_m2 - plant.state.p_m1)
        return np.array(w), np.array(dp), plant.state

    w_paper, _, _ = decel({})
    w_bidir, dp, s = decel(BIDIR)
    t_half = lambda w: int(np.argmax(w < 400 / RPM_PER_RAD_S))  # noqa: E731
    assert t_half(w_bidir) < 0.5 * t_half(w_paper)
    assert s.omega == 0.0  # stopped, and stays: the closed centre holds port B
    assert dp[: t_half(w_bidir)].max() > 1e4  # Δp reversed: the gas compressed in port B brakes


def test_bidirectional_keeps_p_m1_as_port_A_pressure():
    plant = plant_with(BIDIR)
    plant.reset()
    for u_r in (8.0, 2.0):
        run_for(plant, 0.5, u_r=u_r)
        sample = plant.step(5.0, u_r)
        s = plant.state
        assert abs(s.p_m1 - s.p_m2) > 1e5
        assert sample.p_m1 == pytest.approx(s.p_m1, abs=6e3)  # ±0.5 % FS offset, lag


def test_bidirectional_reset_at_rest_and_at_speed_does_not_drift():
    plant = plant_with(BIDIR)
    plant.reset()
    s = plant.state
    assert s.p_m1 == s.p_m2 and s.p_m2 > plant.params.ambient.p_a  # the centre's leak pressure
    s = run_for(plant, 0.5)
    assert s.omega == 0.0
    plant.reset(omega0=800 / RPM_PER_RAD_S)
    w = [plant.step(5.0, 5.0).omega for _ in range(3)]
    assert abs(w[0] * RPM_PER_RAD_S - 800) < 30


def test_plumbing_choice_is_checked():
    with pytest.raises(ParamError, match="rotary.plumbing"):
        with_updates(PlantParams(), {"rotary.plumbing": "reversed"})
