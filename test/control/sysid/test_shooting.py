"""The segment replays: what is computed once per record (spools, measured starts) changes no result."""

from __future__ import annotations

import numpy as np
import pytest
from pneu_control.sysid import shooting
from pneu_control.sysid.excite import excitation_spec, run_excitation
from pneu_control.sysid.record import load_record
from pneu_msgs_py.params.core import with_updates
from pneu_sim.physics.params import PlantParams


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    out = tmp_path_factory.mktemp("excite")
    spec = excitation_spec(("linear", "rotary"), PlantParams(), seed=4, level="quick")
    run_excitation(spec, out, progress=False, hide_plant=True)
    return out / "run.mcap"


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k], equal_nan=True) for k in a)


@pytest.mark.parametrize(("axis", "segment_s"), [("linear", 1.0), ("rotary", 2.0)])
def test_the_record_memo_changes_no_replay(bag, axis, segment_s):
    p = PlantParams()
    offsets = {"p_c1": 1.5e3, "p_c2": -2.0e3} if axis == "linear" else {"p_m1": 0.8e3}
    rec = load_record(bag)
    seg = shooting.segments_of(rec, axis, segment_s)
    assert len(seg) > 10
    first = shooting.simulate(p, rec, seg, offsets, axis)
    assert rec.memo  # the spools and the measured starts are kept ...
    assert _same(first, shooting.simulate(p, rec, seg, offsets, axis))  # ... and give the same
    # another offset and another spool model on the same record: as on a fresh record
    other = with_updates(p, {f"valve_{axis}.omega_n": 0.8 * getattr(p, f"valve_{axis}").omega_n})
    offs2 = {k: -v for k, v in offsets.items()}
    cached = shooting.simulate(other, rec, seg, offs2, axis)
    fresh = shooting.simulate(other, load_record(bag), seg, offs2, axis)
    assert _same(cached, fresh)
    assert not _same(cached, first)


@pytest.mark.parametrize("axis", ["linear", "rotary"])
def test_the_shared_jacobian_is_least_squares_own_to_the_bit(bag, axis, monkeypatch):
    """Problem.jacobian restarts each column's replay where its change can first act: on a
    problem with curve knots, offsets and physical values, it equals scipy's 2-point
    Jacobian of the residuals (what least_squares computes with jac="2-point") exactly, and
    replays fewer periods than a replay per column."""
    from pneu_control.sysid import curve
    from pneu_control.sysid.fit import FitOptions, Problem
    from pneu_sim.physics import replay as rp
    from scipy.optimize._numdiff import approx_derivative

    rec = load_record(bag)
    start = curve.own_curve_plant(PlantParams(), axis)
    knots, _sup = curve.fit_params(axis, start, [rec])
    assert sum("@+" in p.name or "@-" in p.name for p in knots) >= 4
    others = ("linear.A_f", "linear.c_v") if axis == "linear" else ("rotary.J_m", "rotary.k_leak")
    opt = FitOptions(params=(*others, *(p.name for p in knots)))
    prob = Problem(axis, start, [rec], opt, extra=knots)
    rng = np.random.default_rng(3)
    z = np.clip(rng.normal(0.0, 0.3, prob.n_p + prob.n_off), prob.lo, prob.hi)
    z[-1] = prob.hi[-1]  # a coordinate at its bound: the step turns inward, as scipy's
    periods = []
    real = rp.replay_segments

    def counted(*args, **kw):
        periods.append(int(np.sum(args[5])))
        return real(*args, **kw)

    monkeypatch.setattr(rp, "replay_segments", counted)
    fast = prob.jacobian(z)
    monkeypatch.undo()
    ref = approx_derivative(
        prob.residuals, z, method="2-point", rel_step=opt.diff_step, f0=prob.residuals(z),
        bounds=(prob.lo, prob.hi),
    )  # fmt: skip
    assert fast.shape == ref.shape and np.array_equal(fast, ref)
    assert np.count_nonzero(ref[:, prob.n_p - 1]) > 0  # the outermost knot has an effect
    whole = sum(s.lengths.sum() for _r, s in prob.used)
    assert periods[0] == whole and len(periods) <= 1 + prob.n_p + prob.n_off
    assert sum(periods) < 0.9 * (1 + prob.n_p + prob.n_off) * whole


def test_a_refit_starts_from_the_fitted_plant(bag):
    """The bootstrap's refit (fit.refit) starts where the fit ended: its handles mean what they
    meant in the fit (about the curve that fit started from, here with a dead band off the
    start curve's 50 mV grid), so on the fit's own bag it starts at the fit's plant and cost."""
    from dataclasses import replace

    from pneu_control.sysid import curve, model
    from pneu_control.sysid.fit import FitOptions, Problem, refit
    from pneu_sim.physics.valve_curve import port_curves

    rec = load_record(bag)
    base = PlantParams()
    v = base.valve_linear
    shifted = with_updates(
        base, {"valve_linear.du_table": model.shifted_table(v.du_table, -0.0589)}
    )
    start = curve.own_curve_plant(shifted, "linear")
    knots, sup = curve.fit_params("linear", start, [rec])
    opt = FitOptions(params=("linear.c_v", *(p.name for p in knots)), max_nfev=1)
    prob = Problem("linear", start, [rec], opt, extra=knots)
    moved = {p.name: model.base_value(start, p) for p in knots}
    moved = {n: x + (0.013 if n.endswith("@null") else 0.1 * x) for n, x in moved.items()}
    fit = replace(prob.solve(moved, lambda _m: None), curve_support=sup)  # max_nfev=1: the start
    again = refit("linear", base, [rec], fit, opt)
    for a, b in zip(port_curves(again.plant.valve_linear), port_curves(fit.plant.valve_linear)):
        assert np.allclose(a, b, rtol=0.0, atol=1e-9)
    assert again.cost == pytest.approx(fit.cost, rel=1e-9)
