"""Proof on known plants (CI-fast): perturbed twins, hidden from the identifier, found again.

Each case writes a perturbed plant.yaml, runs ``pneu excite --hide-plant`` on it
twice (seed 0: the bag identify gets; seed 1: held out), ``pneu identify`` from
the base config/plant.yaml, ``pneu validate`` on both bags, then checks every
value identify took against the truth (tolerances: pneu_control.sysid.study.TOLERANCE)
and the held-out fit (>= 90 % for x, p_c1, p_c2, p_m1, omega). The quick
excitation (~50 s per axis) keeps this to minutes; tools/sysid_study.py runs
every perturbation alone with the full experiment.
"""

from __future__ import annotations

import json

import pytest
import yaml
from pneu_control.cli.main import main
from pneu_control.sysid import curve, study
from pneu_msgs_py.params.core import flatten
from pneu_sim.physics.plant_file import dump_plant_yaml, load_plant

CASES = {
    # rotary inertia, breakaway friction, a stiffer process, the absolute supply reading
    "inertia+breakaway+n1.35+absolute": [
        "J_m x1.6",
        "breakaway x1.3",
        "n = 1.35",
        "absolute supply",
    ],
    # the valves: shifted flow curve and twice the centre leakage, a near-isothermal process
    "flow+leakage+n1.05": ["flow curve shifted", "leakage x2", "n = 1.05"],
    # inertia, friction and volume together on the motor (issue 21's plant B: found as J_m
    # +49 %, Q_n -46 %, p_s +56 % before the equation-error starts), friction and leakage on
    # the cylinder
    "motorJ+Mc+Vm1+cylinderAf+cv+leak": [
        "motor J_m x1.5, M_c x0.6, V_m1 x1.6",
        "cylinder A_f x1.3, c_v x0.75, leak x1.5",
    ],
}
MIN_FIT = 90.0
# Reached on every signal but one: with the supply read as absolute (a 1 bar gauge supply on
# the cylinder) the rod-side pressure fits 87 % held out. What limits it is not noise (its
# ceiling is 96.7 %) but the supply: identified 2.9 % high (inside its 3 % tolerance), traded
# against the two pressure sensors' common offset -- no segment vents a chamber to the
# atmosphere, which would fix the offsets (see docs/calibration.md, the proof on known plants).
MIN_FIT_EXCEPTIONS = {("inertia+breakaway+n1.35+absolute", "p_c2"): 85.0}
SIGNALS = ("x", "p_c1", "p_c2", "p_m1", "omega")


@pytest.fixture(scope="module", params=list(CASES))
def case(request, tmp_path_factory):
    names = CASES[request.param]
    out = tmp_path_factory.mktemp(request.param.replace("+", "_"))
    base = load_plant()
    truth = study.perturbed_plant(base, names)
    (out / "true_plant.yaml").write_text(dump_plant_yaml(truth))
    for seed in (0, 1):
        argv = ["excite", "--axis", "both", "--level", "quick", "--seed", str(seed)]
        argv += [
            "--plant",
            str(out / "true_plant.yaml"),
            "--out",
            str(out / f"bag{seed}"),
            "--hide-plant",
        ]
        assert main(argv) == 0
    assert main(["identify", str(out / "bag0"), "--out", str(out / "identified.yaml")]) == 0
    assert main(["validate", str(out / "bag0"), str(out / "bag1"), "--plant", str(out / "identified.yaml"), "--out", str(out / "val")]) == 0  # fmt: skip
    return base, truth, out, request.param


def test_identified_values_within_tolerance(case):
    base, truth, out, _ = case
    rep = json.loads((out / "identified.identify.json").read_text())
    ident = load_plant(out / "identified.yaml")
    bad, taken = [], 0
    for row in rep["parameters"]:
        if curve.is_handle(row["name"]):  # a valve's own curve: judged whole, below
            continue
        true = study.true_value(base, truth, row["name"])
        kind, tol = study.TOLERANCE[row["name"]]
        err = (row["value"] - true) / true if kind == "rel" else row["value"] - true
        if row["taken"]:
            taken += 1
            if abs(err) > tol:
                bad.append(
                    f"{row['name']}: {row['value']:.4g} vs true {true:.4g} ({err:+.3g}, tol {tol})"
                )
    for axis in ("linear", "rotary"):  # an own curve (the last stage kept it): as the truth's
        valve = f"valve_{axis}"
        if any(r["name"].startswith(f"{valve}.flow_") for r in rep["parameters"]):
            ports = curve.ports_of(axis, truth)
            err = curve.max_error(ident, truth, valve, ports)
            if err > study.CURVE_TOLERANCE:
                bad.append(f"{valve} curve: {err:.3f} of full flow off at worst")
    assert not bad, bad
    # all but what the data cannot determine: of the 19 fitted (the flow scale and dead band
    # of a valve whose own curve was kept are in its curve)
    assert taken >= 13
    # the motor's exhaust chamber volume is not observable without an exhaust sensor: reported
    assert "rotary.V_m2" in rep["kept_base"]


def test_the_plant_file_says_what_was_identified(case):
    base, _truth, out, _ = case
    tree = yaml.safe_load((out / "identified.yaml").read_text())
    ident = load_plant(out / "identified.yaml")
    assert tree["rotary"]["J_m"]["source"].startswith("identified from bag0/run.mcap (±")
    assert "not identifiable" in tree["rotary"]["V_m2"]["source"]
    assert (
        tree["linear"]["A_c1"] == yaml.safe_load(dump_plant_yaml(base))["linear"]["A_c1"]
    )  # Table 1
    assert flatten(ident)["linear.M"] == flatten(base)["linear.M"]


def test_held_out_validation_fit(case):
    _, _, out, name = case
    rows = json.loads((out / "val" / "validate.json").read_text())
    held = [r for r in rows if r["held_out"]]
    assert len(held) == 1 and held[0]["bag"].endswith("bag1/run.mcap")
    fits = held[0]["fit_percent"]
    assert set(fits) == set(SIGNALS)
    low = {
        k: round(v, 1) for k, v in fits.items() if v < MIN_FIT_EXCEPTIONS.get((name, k), MIN_FIT)
    }
    assert not low, f"held-out fit below {MIN_FIT} %: {low}"
    # one overlay per bag and axis validated (both bags excite both axes)
    pngs = sorted(p.name for p in (out / "val").glob("*.png"))
    assert len(pngs) == 2 * len(rows) and all(
        any(p.endswith(f"_{ax}.png") for p in pngs) for ax in ("linear", "rotary")
    ), pngs
