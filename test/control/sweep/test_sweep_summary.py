"""Sweep statistics against independent computations on tables with known answers."""

import math

import numpy as np
import pytest
from pneu_control.analysis.metrics import WindowSpec
from pneu_control.experiment.catalog import Experiment
from pneu_control.sweep.sampling import Factor
from pneu_control.sweep.summary import band, render_summary, spearman_top, summarise, wilson
from scipy import stats

EXP = Experiment(
    id="e",
    axis="linear",
    title="t",
    reference={},
    duration_s=1.0,
    window=WindowSpec(),
    controllers=("pid", "ladrc", "eso_smc"),
    unit="mm",
    paper={"pid": (1.4, 0.441), "ladrc": (0.8, 0.398), "eso_smc": (0.44, 0.176)},
)
FACTORS = [
    Factor("a", ("linear.M",), 0.0, 1.0),
    Factor("b", ("linear.A_f",), 0.0, 1.0),
    Factor("s[g|x]", ("supply.p_s_linear",), labels=("g", "x"), values=((3e5,), (2e5,))),
]


def _rows(n=40, seed=0):
    rng = np.random.default_rng(seed)
    a, b = rng.random(n), rng.random(n)
    lab = np.where(rng.random(n) < 0.5, "g", "x")
    rows = []
    for s in range(n):
        # eso_smc depends on a only; pid on b (decreasing); ladrc constant 0.7 except trips
        e = {"eso_smc": 0.3 + 0.4 * a[s], "ladrc": 0.7, "pid": 1.5 - b[s]}
        if s % 10 == 0:
            e["ladrc"] = math.nan  # a trip
        for c in ("pid", "ladrc", "eso_smc"):
            rows.append(
                {
                    "sample": s,
                    "experiment": "e",
                    "controller": c,
                    "gains": "paper",
                    "unit": "mm",
                    "e_max": e[c],
                    "rmse": e[c] / 3,
                    "in_band": None,
                    "safety_trip": "overspeed at 0.1 s" if math.isnan(e[c]) else "",
                    "a": a[s],
                    "b": b[s],
                    "s[g|x]": lab[s],
                }
            )
    return rows, a, b


def test_band_is_the_empirical_quantiles_with_failures_worst():
    x = [5.0, 1.0, 3.0, math.nan, 2.0, 4.0]
    b = band(x)
    ref = np.sort([5.0, 1.0, 3.0, np.inf, 2.0, 4.0])
    # inverted CDF: the smallest value whose empirical CDF reaches q
    assert b.q05 == ref[0] and b.median == ref[2] and b.q95 == ref[5] == math.inf
    assert b.failed == 1
    assert b.holds(2.5) and not b.holds(0.5) and b.holds(None) is None


def test_wilson_interval_known_values():
    lo, hi = wilson(0, 10)
    assert lo == 0.0 and hi == pytest.approx(0.2775, abs=1e-4)
    lo, hi = wilson(50, 100)
    assert (lo, hi) == pytest.approx((0.4038, 0.5962), abs=1e-4)


def test_spearman_top_finds_the_driver_and_skips_constants():
    rng = np.random.default_rng(1)
    cols = {"x": rng.random(50), "y": rng.random(50), "const": np.ones(50)}
    y = np.exp(3 * cols["x"]) + 0.01 * rng.random(50)
    top = spearman_top(cols, y)
    assert top[0][0] == "x" and top[0][1] == pytest.approx(stats.spearmanr(cols["x"], y).statistic)
    assert "const" not in [n for n, _ in top]
    assert spearman_top(cols, np.full(50, 2.0)) == []  # a constant result: no ρ, no warning
    assert spearman_top(cols, np.full(50, np.nan)) == []  # all failed


def test_summary_bands_ranking_and_sensitivity():
    rows, a, b = _rows()
    groups, rankings = summarise(rows, FACTORS, [EXP])
    g = {x.controller: x for x in groups}
    eso = 0.3 + 0.4 * a
    assert g["eso_smc"].e_max.median == np.quantile(eso, 0.5, method="inverted_cdf")
    assert g["eso_smc"].paper_e_max_in_band is True  # 0.44 inside [0.3, 0.7]
    assert g["pid"].paper_e_max_in_band is True
    # 4 of 40 LADRC runs tripped (> 5 %): the band reaches 'trip', so 0.8 lies inside it
    assert g["ladrc"].e_max.q95 == math.inf and g["ladrc"].paper_e_max_in_band is True
    assert g["ladrc"].trips == 4 and g["ladrc"].e_max.failed == 4
    assert g["eso_smc"].sensitivity[0][0] == "a" and g["eso_smc"].sensitivity[0][1] > 0.99
    assert g["pid"].sensitivity[0][0] == "b" and g["pid"].sensitivity[0][1] < -0.99
    # the ranking, sample by sample, with a trip counted as the worst
    expected = np.mean([(eso[s] < 0.7 < 1.5 - b[s]) and s % 10 != 0 for s in range(40)])
    (r_e, r_r) = rankings
    assert (r_e.metric, r_r.metric) == ("e_max", "rmse")
    assert r_e.p_ranking == pytest.approx(expected) and r_e.n == 40
    assert r_e.p_eso_lt_ladrc == 1.0  # a tripped LADRC is beaten by any number
    assert r_e.p_ladrc_lt_pid == pytest.approx(
        np.mean([s % 10 != 0 and 0.7 < 1.5 - b[s] for s in range(40)])
    )
    lo, hi = r_e.ci95
    assert lo <= r_e.p_ranking <= hi
    md = render_summary(groups, rankings, 40)
    assert "| e | ladrc | paper | — | 0.7 [0.7–trip] mm |" in md
    assert "P(ESO-SMC < LADRC < PID)" in md
