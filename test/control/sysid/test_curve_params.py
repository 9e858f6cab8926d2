"""The valve curve as fit parameters (sysid.curve) and its direct measurement (sysid.valve_flow)."""

from __future__ import annotations

import numpy as np
import pytest
from pneu_control.sysid import curve, valve_flow
from pneu_control.sysid.record import Record
from pneu_msgs_py.params.core import with_updates
from pneu_sim.physics import kernel as k
from pneu_sim.physics.params import PlantParams
from pneu_sim.physics.plant import Plant
from pneu_sim.physics.valve_curve import FLOW_BOUND, grid, port_curves


def _record(u_lin: np.ndarray, name: str = "synthetic") -> Record:
    """A record whose command visits every voltage of ``u_lin`` long enough to be fitted."""
    n = len(u_lin)
    y = {s: np.zeros(n) for s in ("p_c1", "p_c2", "p_m1", "x", "theta", "omega")}
    return Record(
        path=name,
        name=name,
        stamp_ns=np.arange(n, dtype=np.int64) * 1_000_000,
        y=y,
        u={"linear": np.asarray(u_lin, dtype=float), "rotary": np.full(n, 5.0)},
        commanded=("linear", "rotary"),
        valid={"linear": np.ones(n, bool), "rotary": np.ones(n, bool)},
    )


def _handles_at_start(start, rec):
    params, sup = curve.fit_params("linear", start, [rec])
    return params, sup, {p.name: curve.base_value(start, p.name) for p in params}


def test_start_values_reproduce_the_start_curve():
    """At the start's own values the parameters give the catalogue back (within 0.5 % of
    full flow: only its first mV become the dead band): between knots the
    curve keeps the start's shape."""
    start = PlantParams()
    rec = _record(np.linspace(2.0, 8.0, 60_000))
    params, sup, values = _handles_at_start(start, rec)
    assert {p.name for p in params} >= {"valve_linear.flow_4@null", "valve_linear.flow_2@band"}
    assert sup.knots[("4", "+")] >= 5 and sup.knots[("2", "-")] >= 5
    plant = with_updates(start, curve.updates(start, values))
    assert curve.max_error(plant, start, "valve_linear") < 0.005


def test_knots_where_the_data_are_not_fitted_and_the_tail_meets_full_flow():
    start = PlantParams()
    rec = _record(np.linspace(4.0, 6.0, 40_000))  # never beyond ±1 V
    params, sup, values = _handles_at_start(start, rec)
    reach = max(sup.reach[("4", "+")], sup.reach[("2", "+")])
    assert 5.8 < reach <= 6.2
    assert "no data there" in sup.text()
    # a fitted knot far too high: the unfitted tail bends back to full flow at 10 V
    key = max((p.name for p in params if "@+" in p.name and "flow_4" in p.name), key=len)
    plant = with_updates(start, curve.updates(start, {**values, key: values[key] + 0.2}))
    u, f4, _ = port_curves(plant.valve_linear)
    assert np.interp(10.0, u, f4) == pytest.approx(1.0)
    assert np.all(np.diff(f4) >= 0.0)


def test_any_values_within_the_bounds_give_a_valid_monotone_curve():
    start = PlantParams()
    rec = _record(np.linspace(1.0, 9.0, 80_000))
    params, _sup, _values = _handles_at_start(start, rec)
    rng = np.random.default_rng(5)
    for _ in range(30):
        vals = {p.name: float(rng.uniform(p.lo, min(p.hi, p.lo + 0.4))) for p in params}
        plant = with_updates(start, curve.updates(start, vals))  # validated: would raise
        _u, f4, f2 = port_curves(plant.valve_linear)
        assert np.all(np.diff(f4) >= 0.0) and np.all(np.diff(f2) <= 0.0)
        assert np.max(np.abs(f4)) <= FLOW_BOUND and np.max(np.abs(f2)) <= FLOW_BOUND


def test_the_dead_band_parameters_move_and_widen_the_zero_flow_region():
    start = PlantParams()
    rec = _record(np.linspace(3.0, 7.0, 60_000))
    _params, _sup, values = _handles_at_start(start, rec)
    moved = {**values, "valve_linear.flow_4@null": 0.2, "valve_linear.flow_4@band": 0.3}
    plant = with_updates(start, curve.updates(start, moved))
    u, f4, _ = port_curves(plant.valve_linear)
    g = grid()
    zero = g[np.interp(g, u, f4) == 0.0]
    assert zero.min() == pytest.approx(4.9, abs=0.011) and zero.max() == pytest.approx(
        5.5, abs=0.011
    )


def _pulse_record(plant: Plant, amplitudes, guard_m=0.035):
    """Open-loop valve pulses of growing size, alternating direction from rest, each cut
    when the piston passes the guard, then 0.4 s blocked: a record of the twin's sensors."""
    u = [5.0] * 300
    samples = [plant.reset(x0=-guard_m)]
    for _ in range(299):
        samples.append(plant.step(5.0, 5.0))
    for a in amplitudes:
        for sign in (1.0, -1.0):
            for i in range(1500):
                s = samples[-1]
                if i > 0 and sign * s.x > guard_m:
                    break
                u.append(5.0 + sign * a)
                samples.append(plant.step(5.0 + sign * a, 5.0))
            for _ in range(400):
                u.append(5.0)
                samples.append(plant.step(5.0, 5.0))
    rec = _record(np.array(u), "pulses")
    for name in ("p_c1", "p_c2", "x"):
        rec.y[name] = np.array([getattr(s, name) for s in samples])
    return rec


def test_the_chambers_measure_the_valve_curve_at_known_volume():
    """A twin with a curve of its own (dead band 4.5-5.4 V, linear past it): the direct
    estimate from pulses at four sizes finds it within 2 % of full flow where it has data."""
    own = {
        "valve_linear.u_curve": (0.0, 3.0, 4.5, 5.4, 6.4, 10.0),
        "valve_linear.flow_4": (-1.0, -0.3, 0.0, 0.0, 0.3, 1.0),
        "valve_linear.flow_2": (0.8, 0.24, 0.0, 0.0, -0.24, -0.8),
    }
    params = with_updates(PlantParams(), own)
    plant = Plant(params, seed=4)
    rec = _pulse_record(plant, (0.6, 0.9, 1.3, 1.7))
    _st, prm, _ = plant.kernel_arrays()
    ps = params.sensors.pressure
    offs = {n: prm[k.P_POFF + i] / ps.v_fs * ps.fs for i, n in enumerate(("p_c1", "p_c2"))}
    est = valve_flow.estimate_curve(params, [rec], {rec.path: offs})
    u_t, f4_t, f2_t = port_curves(params.valve_linear)
    for port, f_t, sign in (("4", f4_t, 1.0), ("2", f2_t, -1.0)):
        u, g, _cnt = est[port]
        have = np.isfinite(g)
        err = np.abs(g[have] - sign * np.interp(u[have], u_t, f_t))
        assert have.sum() >= 8, port  # the null and the four sizes either way
        assert err.max() <= 0.02, (port, u[have][np.argmax(err)], err.max())
        assert np.any(u[have] < 4.0) and np.any(u[have] > 6.0)


def test_the_curve_error_splits_where_fitted_and_beyond():
    # a valve whose port-4 flow differs from the catalogue's only above 8 V: inside 3-7 V
    # the curves agree, beyond they do not (by 0.05 of full flow per volt above 8 V)
    base = PlantParams()
    u, f4, f2 = port_curves(base.valve_linear)
    f4b = np.where(u > 8.0, f4 - 0.05 * (u - 8.0), f4)
    other = with_updates(
        base,
        {
            "valve_linear.u_curve": tuple(float(x) for x in u),
            "valve_linear.flow_4": tuple(float(x) for x in f4b),
            "valve_linear.flow_2": tuple(float(x) for x in f2),
        },
    )
    fitted = {"4": (3.0, 7.0), "2": (3.0, 7.0)}
    whole = curve.max_error(other, base, "valve_linear")
    inside = curve.max_error(other, base, "valve_linear", within=fitted)
    beyond = curve.max_error(other, base, "valve_linear", within=fitted, outside=True)
    assert whole > 0.05
    assert inside == pytest.approx(0.0, abs=1e-9)
    assert beyond == pytest.approx(whole)


def test_a_valve_built_with_lists_gives_the_curve_of_its_tuples():
    """The curve's start shape is memoised on the (hashable) valve params; a params object
    built directly with lists (not through the loader, which makes tuples) is computed
    afresh and gives the same curve, to the bit."""
    import dataclasses

    start = PlantParams()
    rec = _record(np.linspace(2.0, 8.0, 60_000))
    params, _sup, values = _handles_at_start(start, rec)
    moved = {n: x + (0.01 if n.endswith("@null") else 0.05 * x) for n, x in values.items()}
    v = start.valve_linear
    listed = dataclasses.replace(v, du_table=list(v.du_table), flow_table=list(v.flow_table))
    with pytest.raises(TypeError):
        hash(listed)
    as_lists = dataclasses.replace(start, valve_linear=listed)
    assert curve.base_value(as_lists, params[0].name) == curve.base_value(start, params[0].name)
    assert curve.updates(as_lists, moved) == curve.updates(start, moved)
