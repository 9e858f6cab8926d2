"""The replay kernel: the twin's own physics on given voltages, outputs without noise or quantisation."""

from __future__ import annotations

import numpy as np
import pytest
from pneu_msgs_py.params.core import with_updates
from pneu_sim.physics import kernel as k
from pneu_sim.physics import replay as rp
from pneu_sim.physics.params import K_SEAL_ESTIMATE, PlantParams
from pneu_sim.physics.plant import Plant


def _quiet(p: PlantParams) -> PlantParams:
    return with_updates(
        p,
        {
            "sensors.pressure.sigma_v": 0.0,
            "sensors.pressure.accuracy_fs": 0.0,
            "sensors.laser.sigma_m": 0.0,
        },
    )


def test_replay_matches_the_plant_within_the_daq_quantum():
    """From the plant's own state, the replay gives what its sensors read, to the AI/encoder LSB."""
    p = _quiet(PlantParams())
    plant = Plant(p, seed=1)
    plant.reset(x0=-0.02)
    rng = np.random.default_rng(0)
    ul = 5.0 + np.repeat(rng.uniform(-1.5, 1.5, 40), 50)
    ur = 5.6 + np.repeat(rng.uniform(-0.3, 0.4, 40), 50)
    plant.run(np.full(200, 5.0), np.full(200, 5.6))  # a state in motion, not the reset one
    st0 = plant._st.copy()
    out = plant.run(ul, ur)
    prm = rp.replay_params(p)
    sim = rp.replay(st0.copy(), prm, ul, ur)
    lsb_p = 20.0 / 2**16 * 1e5  # 16-bit AI over ±10 V, 1e5 Pa/V
    lsb_x = 10.0 / 2**16 * 0.16 / 5.0
    assert np.max(np.abs(sim[:, rp.R_PC1] - out[:, k.O_PC1])) <= lsb_p
    assert np.max(np.abs(sim[:, rp.R_PM1] - out[:, k.O_PM1])) <= lsb_p
    assert np.max(np.abs(sim[:, rp.R_X] - out[:, k.O_X])) <= lsb_x
    # the encoder's speed is the mean speed over the period, quantised to one count per period
    q = 2 * np.pi / 4000 / 1e-3
    assert np.max(np.abs(sim[:, rp.R_OM] - out[:, k.O_OM])) <= q + 1e-9
    assert np.ptp(out[:, k.O_X]) > 0.02 and np.ptp(out[:, k.O_OM]) > 50.0  # it did move


@pytest.mark.parametrize("axes", ["linear", "rotary"])
def test_one_axis_replay_is_the_same_arithmetic(axes):
    # exact with the torque transmission module's coupling off (the axes then share no
    # state); with it on, a one-axis replay holds the other axis at its start state
    p = with_updates(PlantParams(), {"coupling.k_seal": 0.0, "coupling.mu_sleeve": 0.0})
    prm = rp.replay_params(p)
    plant = Plant(p, seed=0)
    plant.reset()
    st = plant._st.copy()
    ul = np.linspace(4.0, 6.5, 300)
    ur = np.linspace(5.2, 6.2, 300)
    both = rp.replay(st.copy(), prm, ul, ur, "both")
    one = rp.replay(st.copy(), prm, ul, ur, axes)
    cols = [rp.R_PC1, rp.R_PC2, rp.R_X] if axes == "linear" else [rp.R_PM1, rp.R_TH, rp.R_OM]
    assert np.array_equal(both[:, cols], one[:, cols])


@pytest.mark.parametrize("axes", ["linear", "rotary"])
def test_one_axis_replay_with_coupling_holds_the_other_axis(axes):
    p = with_updates(PlantParams(), {"coupling.k_seal": K_SEAL_ESTIMATE})
    prm = rp.replay_params(p)
    plant = Plant(p, seed=0)
    plant.reset()
    st = plant._st.copy()
    ul = np.linspace(4.0, 6.5, 300)
    ur = np.linspace(5.2, 6.2, 300)
    both = rp.replay(st.copy(), prm, ul, ur, "both")
    one = rp.replay(st.copy(), prm, ul, ur, axes)
    cols = [rp.R_PC1, rp.R_PC2] if axes == "linear" else [rp.R_PM1, rp.R_OM]
    assert not np.array_equal(both[:, cols], one[:, cols])  # the axes do couple
    assert np.allclose(both[:, cols], one[:, cols], rtol=0.02, atol=1.0)  # a little


def test_rotary_replay_fed_the_recorded_chamber_pressures_follows_the_coupled_one():
    p = with_updates(PlantParams(), {"coupling.k_seal": K_SEAL_ESTIMATE})
    prm = rp.replay_params(p)
    plant = Plant(p, seed=0)
    plant.reset()
    st = plant._st.copy()
    n = 600
    ul = 5.0 + 1.5 * np.sin(np.arange(n) * 0.02)  # the piston moves: p_c1, p_c2 swing
    ur = np.full(n, 6.5)
    both = rp.replay(st.copy(), prm, ul, ur, "both")
    fed = np.column_stack([both[:, rp.R_PC1], both[:, rp.R_PC2]])
    fed = np.vstack([[st[k.S_PC1], st[k.S_PC2]], fed[:-1]])  # at the start of each period
    fed[10] = np.nan  # a lost sample keeps the previous values
    held = rp.replay(st.copy(), prm, ul, ur, "rotary")
    feed = rp.replay(st.copy(), prm, ul, ur, "rotary", p_c=fed)
    err = lambda a: np.abs(a[:, rp.R_OM] - both[:, rp.R_OM]).max()  # noqa: E731
    assert err(feed) < 0.2 * err(held)
    with pytest.raises(ValueError, match="p_c"):
        rp.replay(st.copy(), prm, ul, ur, "linear", p_c=fed)


def test_spool_trajectory_is_the_kernels_spool():
    p = PlantParams()
    prm = rp.replay_params(p)
    u = 5.0 + np.repeat([0.0, 1.0, -0.5, 0.02, 0.0], 20)
    traj = rp.spool_trajectory(prm, "linear", u)
    st = np.zeros(k.N_STATE)
    st[k.S_SL] = st[k.S_YL] = 5.0
    for i in range(len(u)):
        assert traj[i].tolist() == [st[k.S_SL], st[k.S_SDL], st[k.S_YL]]
        for _ in range(p.sim.n_sub):
            k.spool_step.py_func(
                st, prm, k.P_VALVE_L, k.S_SL, k.S_SDL, k.S_YL, k.ao_value(prm, u[i])
            )


def test_exhaust_pressure_balances_the_silencer():
    p = PlantParams()
    prm = rp.replay_params(p)
    kbar = rp.mean_vane_factor(prm)
    assert rp.exhaust_pressure(prm, p.ambient.p_a, 0.0, kbar) == pytest.approx(p.ambient.p_a)
    lo = rp.exhaust_pressure(prm, 2.0e5, 50.0, kbar)
    hi = rp.exhaust_pressure(prm, 2.0e5, 120.0, kbar)
    assert p.ambient.p_a < lo < hi < 2.0e5  # faster motor, more swept flow, higher p_m2


def test_exhaust_pressure_compiled_is_the_python_bisection():
    """The compiled bisection gives the same bits as its Python source."""
    prm = rp.replay_params(PlantParams())
    kbar = rp.mean_vane_factor(prm)
    rng = np.random.default_rng(4)
    for p_m1, omega in zip(rng.uniform(0.9e5, 6e5, 200), rng.uniform(-50.0, 200.0, 200)):
        fast = rp.exhaust_pressure(prm, p_m1, omega, kbar)
        assert fast == rp._exhaust_pressure.py_func(prm, p_m1, omega, kbar)


@pytest.mark.parametrize("axes", ["both", "linear", "rotary"])
def test_segments_in_parallel_are_the_one_by_one_replays(axes):
    """replay_segments (numba threads) returns, bit for bit, each segment's replay() in turn."""
    p = PlantParams()
    prm = rp.replay_params(p)
    plant = Plant(p, seed=2)
    plant.reset(x0=0.01)
    rng = np.random.default_rng(5)
    n = 3000
    ul = 5.0 + np.repeat(rng.uniform(-1.2, 1.2, n // 50), 50)
    ur = 5.5 + np.repeat(rng.uniform(-0.2, 0.5, n // 50), 50)
    starts = np.array([0, 170, 900, 901, 2500])
    lengths = np.array([170, 600, 0, 1400, 500])
    states = []
    for _ in starts:  # different start states: the plant moved on between them
        plant.run(np.full(37, 5.6), np.full(37, 5.8))
        states.append(plant._st.copy())
    states = np.array(states)
    pc = None
    if axes == "rotary":
        pc = np.column_stack([np.linspace(2e5, 3e5, n), np.linspace(3e5, 2e5, n)])
        pc[1000:1010] = np.nan  # a lost sample keeps the previous values
    batch = rp.replay_segments(states, prm, ul, ur, starts, lengths, axes, pc)
    kept = states.copy()
    one = [
        rp.replay(
            states[s].copy(),
            prm,
            ul[a : a + m],
            ur[a : a + m],
            axes,
            None if pc is None else pc[a : a + m],
        )
        for s, (a, m) in enumerate(zip(starts, lengths))
    ]
    assert np.array_equal(batch, np.concatenate(one))
    assert np.array_equal(states, kept)  # the start states are not modified
    with pytest.raises(ValueError, match="inside the voltages"):
        rp.replay_segments(states, prm, ul, ur, starts + 1000, lengths, axes, pc)


@pytest.mark.parametrize("axes", ["both", "linear", "rotary"])
def test_a_segment_restarted_from_its_trace_replays_the_same_bits(axes):
    """The state kept for each period (trace) starts the rest of a segment again, exactly."""
    prm = rp.replay_params(PlantParams())
    rng = np.random.default_rng(8)
    n = 2000
    ul = 5.0 + np.repeat(rng.uniform(-1.5, 1.5, n // 40), 40)
    ur = 5.5 + np.repeat(rng.uniform(-0.3, 0.6, n // 40), 40)
    st = np.zeros(k.N_STATE)
    st[[k.S_PC1, k.S_PC2, k.S_PM1, k.S_PM2]] = [2.5e5, 2.0e5, 1.5e5, 1.1e5]
    st[[k.S_SL, k.S_YL, k.S_SR, k.S_YR]] = [5.0, 5.0, 5.5, 5.5]
    starts, lengths = np.array([5, 1100]), np.array([900, 850])
    pc = np.column_stack([np.full(n, 2.4e5), np.full(n, 2.1e5)]) if axes == "rotary" else None
    trace = np.full((lengths.sum(), k.N_STATE), np.nan)
    whole = rp.replay_segments(np.array([st, st]), prm, ul, ur, starts, lengths, axes, pc, trace)
    assert np.array_equal(whole, rp.replay_segments(np.array([st, st]), prm, ul, ur, starts, lengths, axes, pc))  # fmt: skip
    assert np.array_equal(trace[0], st) and np.array_equal(trace[900], st)
    for j in (1, 333, 899):
        again = rp.replay_segments(trace[j][None], prm, ul, ur, starts[:1] + j, lengths[:1] - j, axes, pc)  # fmt: skip
        assert np.array_equal(again, whole[j:900])
    with pytest.raises(ValueError, match="trace"):
        rp.replay_segments(np.array([st, st]), prm, ul, ur, starts, lengths, axes, pc, trace[:5])


def test_the_opening_envelope_bounds_every_substep_s_opening():
    p = PlantParams()
    prm = rp.replay_params(p)
    u = 5.0 + np.repeat([0.0, 2.0, -0.7, 0.03, 0.0, 4.9], 15)
    env = rp.opening_envelope(prm, "linear", u)
    st = np.zeros(k.N_STATE)
    st[k.S_SL] = st[k.S_YL] = 5.0
    for i in range(len(u)):
        ys = []
        for _ in range(p.sim.n_sub):
            ys.append(k.spool_step.py_func(st, prm, k.P_VALVE_L, k.S_SL, k.S_SDL, k.S_YL, k.ao_value(prm, u[i])))  # fmt: skip
        assert env[i].tolist() == [min(ys), max(ys)]
    assert np.array_equal(rp.spool_trajectory(prm, "linear", u)[1:, 2], [min(max(y, lo), hi) for y, (lo, hi) in zip(rp.spool_trajectory(prm, "linear", u)[1:, 2], env[:-1])])  # fmt: skip


def test_changed_openings_names_the_valve_and_the_voltages_its_changed_cells_are_read_at():
    p = PlantParams()
    prm = rp.replay_params(p)
    assert rp.changed_openings(prm, prm.copy()) == ("linear", np.inf, -np.inf)
    for axis, base in (("linear", k.P_VALVE_L), ("rotary", k.P_VALVE_R)):
        other = prm.copy()
        other[base + k.VB_TAB2 + 600 : base + k.VB_TAB2 + 650] += 1e-3  # port 2, 6.00-6.49 V
        other[base + k.VB_TAB4 + 610] -= 1e-3
        ax, lo, hi = rp.changed_openings(prm, other)
        assert ax == axis and lo <= 5.99 and hi >= 6.50 and lo >= 5.9 and hi <= 6.6
        other[base + k.VB_TAB4 + 1] += 1e-3  # by the first cell: read at any opening below
        assert rp.changed_openings(prm, other)[1] == -np.inf
    moved = prm.copy()
    moved[k.P_VALVE_L + k.VB_ALEAK] *= 1.1  # the centre leak: every opening
    assert rp.changed_openings(prm, moved) is None
    both = prm.copy()
    both[[k.P_VALVE_L + k.VB_TAB4 + 600, k.P_VALVE_R + k.VB_TAB4 + 600]] += 1e-3
    assert rp.changed_openings(prm, both) is None
