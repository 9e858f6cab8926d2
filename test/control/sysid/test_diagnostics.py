"""Residual diagnostics on synthetic residuals: noise passes, a bias tied to the operating point
is called a mismatch, the Ljung-Box test tells white from coloured."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pneu_control.sysid import diagnostics as dg
from pneu_control.sysid.record import Record
from pneu_control.sysid.shooting import Segments

T = 1e-3
N = 40_000


def _smooth_noise(rng, tau_s: float) -> np.ndarray:
    """A smooth random process of unit spread (white noise through a first-order lag)."""
    a = T / tau_s
    w = rng.normal(0.0, 1.0, N)
    out = np.empty(N)
    acc = 0.0
    for i in range(N):
        acc += a * (w[i] - acc)
        out[i] = acc
    return out / np.std(out)


def _record(rng) -> Record:
    """A cylinder under a dithered valve, each operating point its own random process (so the
    regions are not one another in disguise)."""
    u = 5.0 + 0.5 * _smooth_noise(rng, 0.5) + rng.normal(0.0, 0.2, N)
    dp = _smooth_noise(rng, 0.3)
    y = {
        "x": 0.02 * _smooth_noise(rng, 1.0),
        "p_c1": 2.2e5 + 2e4 * dp,
        "p_c2": 2.4e5 - 1e4 * dp + 5e3 * _smooth_noise(rng, 0.2),
        "p_m1": np.full(N, 1.013e5),
        "theta": np.zeros(N),
        "omega": np.zeros(N),
    }
    return Record(
        path="synthetic", name="synthetic", stamp_ns=np.arange(N, dtype=np.int64) * 1_000_000,
        y=y, u={"linear": u, "rotary": np.full(N, 5.0)}, commanded=("linear",),
        valid={"linear": np.ones(N, bool), "rotary": np.ones(N, bool)}, period_s=T,
    )  # fmt: skip


def _piece(rec: Record, residual: dict[str, np.ndarray]) -> dg.Piece:
    """The record cut in 1 s segments, the 'twin' = measurement minus ``residual``."""
    starts = np.arange(20, N - 1100, 1000)
    seg = Segments(starts, np.full(len(starts), 1000))
    idx = seg.index
    return dg.Piece(rec, seg, {n: rec.y[n][idx] - residual[n][idx] for n in residual})


SIGMA = {"x": 1e-4, "p_c1": 200.0, "p_c2": 200.0}


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_noise_and_random_start_errors_are_not_a_mismatch(seed):
    rng = np.random.default_rng(seed)
    rec = _record(rng)
    res = {n: rng.normal(0.0, s, N) for n, s in SIGMA.items()}
    # a start error of random sign in each 1 s segment, decaying (what a restart leaves)
    tt = (np.arange(N) - 20) % 1000 * T
    jumps = np.repeat(rng.normal(0.0, 1.0, N // 1000 + 1), 1000)[:N]
    res["p_c1"] = res["p_c1"] + 800.0 * jumps * np.exp(-tt / 0.2)
    d = dg.diagnose("linear", [_piece(rec, res)], SIGMA)
    assert d.warning == "" and d.evidence == []
    for s in ("x", "p_c2"):
        sd = d.signals[s]
        assert sd.noise_share == pytest.approx(1.0, rel=0.05)  # the residual is the noise
        assert sd.lb_p > 1e-3  # white
        assert max(t.share for t in sd.regions) < dg.MIN_SHARE
    assert d.signals["p_c1"].lb_p < 1e-6  # the start errors are not white ...
    assert max(t.share for t in d.signals["p_c1"].regions) < dg.MIN_SHARE  # ... nor a mismatch


def test_a_flow_error_near_the_null_is_called_where_it_is():
    """x drifts where the valve is just above the null (a flow curve of another shape there):
    the warning names the valve region and the direction of the drift."""
    rng = np.random.default_rng(7)
    rec = _record(rng)
    u = rec.u["linear"]
    near = ((u > 5.05) & (u < 5.4)).astype(float)
    drift = np.zeros(N)  # the residual integrates +2 mm/s while near the null, per segment
    for a in range(20, N, 1000):
        drift[a : a + 1000] = np.cumsum(near[a : a + 1000]) * T * 2e-3
    res = {n: rng.normal(0.0, s, N) for n, s in SIGMA.items()}
    res["x"] = res["x"] + drift
    d = dg.diagnose("linear", [_piece(rec, res)], SIGMA)
    assert d.warning.startswith("warning: structural mismatch on the linear axis")
    sig, region, points, p = d.evidence[0]
    assert (sig, region) == ("x", "valve") and p < dg.ALPHA / d.tests and points > 0.25
    test = next(t for t in d.signals["x"].regions if t.region == "valve")
    assert test.by_growth and test.share > 0.5
    top = max(test.bins, key=lambda b: b.growth)
    assert 5.0 <= top.lo and top.hi <= 5.6 and top.growth > 1e-3  # m/s: the drift is there
    assert "x drifting" in d.warning and "by valve" in d.warning


def test_a_pressure_offset_by_position_is_a_mismatch_and_reported_per_segment():
    rng = np.random.default_rng(8)
    rec = _record(rng)
    res = {n: rng.normal(0.0, s, N) for n, s in SIGMA.items()}
    res["p_c2"] = res["p_c2"] + np.where(
        rec.y["x"] > 0.015, 1500.0, 0.0
    )  # a position-dependent leak
    d = dg.diagnose("linear", [_piece(rec, res)], SIGMA)
    assert any(
        s == "p_c2" and r in ("position", "pressure difference") for s, r, _e, _p in d.evidence
    )
    rows = d.segments
    assert rows and all(r.kind == "window" for r in rows)  # no design: 5 s windows
    worst = d.worst_segments(1)[0]
    assert worst.fit_level["p_c2"] < max(r.fit_level["p_c2"] for r in rows)
    doc = d.to_dict()
    assert doc["structural_mismatch"] is True and doc["evidence"][0]["signal"] == "p_c2"


def test_ljung_box_tells_white_from_coloured():
    rng = np.random.default_rng(0)
    white = rng.normal(size=5000)
    ar = np.zeros(5000)
    for i in range(1, 5000):
        ar[i] = 0.5 * ar[i - 1] + white[i]
    q_w, p_w = dg.ljung_box([white])
    q_a, p_a = dg.ljung_box([ar])
    assert p_w > 0.01 and p_a < 1e-10
    # Q = N(N+2) Σ ρ_k²/(N-k): with the AR(1)'s ρ_k = 0.5^k, about N Σ 0.25^k = N/3
    assert q_a == pytest.approx(5000 / 3, rel=0.2)
    assert math.isfinite(q_w)
