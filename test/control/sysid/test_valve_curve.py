"""A valve of another shape than the catalogue's, identified as a curve (issue 21, item 2).

The hidden plant's linear valve has a flow-vs-voltage curve of its own near the
null: a wider dead band off the null (its centre 45 mV below 5 V on port 4),
linear (not progressive) past it, a steeper side above the null than below,
and port 2 with a dead band of its own; with 1.8x the centre leakage and 1.5x
the viscous friction. Its rotary axis differs inside the model (inertia,
Coulomb torque and inlet volume together). ``pneu excite`` runs it twice
(seed 11 for identify, seed 22 held out); identify starts from
config/plant.yaml. The identified curve must be within 5 % of full flow at
every voltage, J_m within 10 %, and the held-out fit >= 90 % on every signal.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from pneu_control.cli.main import main
from pneu_control.sysid import curve
from pneu_msgs_py.params.core import with_updates
from pneu_sim.physics.plant_file import dump_plant_yaml, load_plant
from pneu_sim.physics.valve_curve import catalogue_curve, grid, port_curves

SIGNALS = ("x", "p_c1", "p_c2", "p_m1", "omega")


def _port(cat, below, above):
    """A port's g (non-decreasing): the catalogue ``cat`` (u, g) beyond the outermost points
    of ``below`` and ``above``, those points near the null."""
    u, g = cat
    lo, hi = below[0][0], above[-1][0]
    pts = [(x, y) for x, y in zip(u, g) if x < lo - 1e-9] + below + above
    pts += [(x, y) for x, y in zip(u, g) if x > hi + 1e-9]
    return np.array([p[0] for p in pts]), np.array([p[1] for p in pts])


def other_shape_plant(base):
    """The hidden plant (see the module docstring)."""
    v = base.valve_linear
    u, f4, _f2 = catalogue_curve(v.du_table, v.flow_table)
    u4, g4 = _port((u, f4), [(3.34, -0.26), (3.80, -0.12), (4.50, 0.0)], [(5.40, 0.0), (6.0, 0.20), (6.66, 0.26)])  # fmt: skip
    u2, g2 = _port((u, f4), [(3.34, -0.26), (3.80, -0.14), (4.60, 0.0)], [(5.35, 0.0), (6.0, 0.18), (6.66, 0.26)])  # fmt: skip
    uu = np.union1d(u4, u2)
    return with_updates(
        base,
        {
            "valve_linear.u_curve": tuple(float(x) for x in uu),
            "valve_linear.flow_4": tuple(float(x) for x in np.interp(uu, u4, g4)),
            "valve_linear.flow_2": tuple(float(-x) for x in np.interp(uu, u2, g2)),
            "valve_linear.leak_fraction": 1.8 * v.leak_fraction,
            "linear.c_v": 1.5 * base.linear.c_v,
            "rotary.J_m": 1.4 * base.rotary.J_m,
            "rotary.M_c": 1.2 * base.rotary.M_c,
            "rotary.V_m1": 1.3 * base.rotary.V_m1,
        },
    )


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("other_shape")
    base = load_plant()
    truth = other_shape_plant(base)
    (out / "true_plant.yaml").write_text(dump_plant_yaml(truth))
    for seed in (11, 22):
        argv = ["excite", "--axis", "both", "--level", "quick", "--seed", str(seed)]
        argv += ["--plant", str(out / "true_plant.yaml"), "--out", str(out / f"bag{seed}")]
        assert main([*argv, "--hide-plant"]) == 0
    assert main(["identify", str(out / "bag11"), "--out", str(out / "identified.yaml")]) == 0
    argv = ["validate", str(out / "bag11"), str(out / "bag22"), "--plant"]
    assert main([*argv, str(out / "identified.yaml"), "--out", str(out / "val")]) == 0
    return base, truth, out


def test_the_hidden_curve_is_not_the_catalogue_s(run):
    base, truth, _ = run
    assert curve.max_error(base, truth, "valve_linear") > 0.10  # the test has teeth


def test_identified_curve_within_5_percent_of_full_flow_at_every_voltage(run):
    _base, truth, out = run
    ident = load_plant(out / "identified.yaml")
    g = grid()
    for port in ("4", "2"):
        u_i, *f_i = port_curves(ident.valve_linear)
        u_t, *f_t = port_curves(truth.valve_linear)
        k = 0 if port == "4" else 1
        mine = np.interp(g, u_i, f_i[k]) * ident.valve_linear.Q_n / truth.valve_linear.Q_n
        err = np.abs(mine - np.interp(g, u_t, f_t[k]))
        worst = int(np.argmax(err))
        assert err[worst] <= 0.05, f"port {port}: {err[worst]:.3f} of full flow at {g[worst]:.2f} V"


def test_the_plant_file_holds_the_curve_and_its_provenance(run):
    _base, _truth, out = run
    tree = yaml.safe_load((out / "identified.yaml").read_text())
    v = tree["valve_linear"]
    u = v["u_curve"]["value"]
    assert len(u) >= 10 and u == sorted(u)
    f4, f2 = v["flow_4"]["value"], v["flow_2"]["value"]
    assert np.all(np.diff(f4) >= 0.0) and np.all(np.diff(f2) <= 0.0)  # monotone per port
    src = v["u_curve"]["source"]
    assert src.startswith("identified from bag11/run.mcap: the valve's own curve")
    assert "samples" in src and "pulse segments" in src and "no data there" in src
    assert "the unit of the identified curve" in v["Q_n"]["source"]


def test_rotary_inertia_within_10_percent(run):
    _base, truth, out = run
    rep = json.loads((out / "identified.identify.json").read_text())
    row = next(r for r in rep["parameters"] if r["name"] == "rotary.J_m")
    assert row["taken"]
    assert abs(row["value"] / truth.rotary.J_m - 1.0) <= 0.10, row["value"]


def test_held_out_fit_on_every_signal_of_both_axes(run):
    _, _, out = run
    rows = json.loads((out / "val" / "validate.json").read_text())
    held = [r for r in rows if r["held_out"]]
    assert len(held) == 1 and held[0]["bag"].endswith("bag22/run.mcap")
    fits = held[0]["fit_percent"]
    assert set(fits) == set(SIGNALS)
    low = {k: round(v, 1) for k, v in fits.items() if v < 90.0}
    assert not low, f"held-out fit below 90 %: {low}"
