"""The identified plant.yaml: sources with intervals, base leaves and keys kept, nothing overwritten."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from pneu_control.sysid import model
from pneu_control.sysid.fit import AxisFit
from pneu_control.sysid.identify import Identification, NoiseEstimate, write_plant
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.paths import config_file
from pneu_sim.physics.plant_file import load_plant


def _ident(base):
    names = ["rotary.J_m", "rotary.V_m2", "valve_rotary.dead_band"]
    values = [5.6e-5, 3e-6, 0.12]
    params = [p for p in model.AXIS_PARAMS["rotary"] if p.name in names]
    plant = model.apply(base, tuple(params), [values[names.index(p.name)] for p in params])
    fit = AxisFit(
        axis="rotary",
        names=names,
        units=["kg*m^2", "m^3", "V"],
        base=[3.5e-5, 1e-5, 0.0],
        value=values,
        sigma=[0.5e-6, 5e-5, 0.002],
        corr=np.eye(3),
        offsets={"b.mcap": {"p_m1": 2000.0}},
        offsets_sigma={"b.mcap": {"p_m1": 50.0}},
        cost_start=10.0,
        cost=1.0,
        nfev=5,
        wall_s=1.0,
        inflation=2.0,
        n_residuals=100,
        status="ok",
        plant=plant,
    )
    noise = {"x": NoiseEstimate("x", 9e-5, 4000)}
    from pneu_msgs_py.params.core import with_updates

    plant = with_updates(plant, {"sensors.laser.sigma_m": 9e-5})
    return Identification(
        base, plant, {"rotary": fit}, noise, ["/data/exc0/run.mcap"], kept_base=["rotary.V_m2"]
    )


def test_written_file_loads_and_says_where_each_value_came_from(tmp_path):
    base = load_plant()
    tree = yaml.safe_load(config_file("plant.yaml").read_text())
    tree["rotary"]["J_m"]["range"] = [1e-5, 1e-4]  # an uncertainty of the base: measured now
    tree["rotary"]["M_c"]["range"] = [0.1, 0.2]  # not identified here: kept as it is
    out = write_plant(_ident(base), tree, tmp_path / "p.yaml")
    text = out.read_text()
    got = yaml.safe_load(text)
    assert got["rotary"]["J_m"]["value"] == 5.6e-5
    rel = f"{100 * (1.96 * 0.5e-6 / 5.6e-5):.2g}"  # 95 % half-width / value
    assert got["rotary"]["J_m"]["source"] == f"identified from exc0/run.mcap (±{rel} %)"
    assert got["rotary"]["J_m"]["range"] == pytest.approx([5.6e-5 - 0.98e-6, 5.6e-5 + 0.98e-6])
    assert got["rotary"]["M_c"]["range"] == [0.1, 0.2]
    assert got["rotary"]["V_m2"]["value"] == 1e-5  # not identifiable: the base value, said so
    assert got["rotary"]["V_m2"]["source"].startswith("not identifiable from exc0/run.mcap")
    assert got["valve_rotary"]["du_table"]["value"][1] == pytest.approx(0.36 + 0.12)
    assert "shifted by +0.120 V (±0.004 V)" in got["valve_rotary"]["du_table"]["source"]
    assert got["sensors"]["laser"]["sigma_m"]["source"].startswith(
        "identified from the quiet segments"
    )
    assert got["linear"]["A_c1"] == tree["linear"]["A_c1"]  # Table 1 untouched
    del got["rotary"]["J_m"]["range"], got["rotary"]["M_c"]["range"]
    from pneu_sim.physics.plant_file import params_from_tree

    p = params_from_tree(got)
    assert p.rotary.J_m == 5.6e-5 and p.rotary.V_m2 == base.rotary.V_m2
    assert (tmp_path / "p.identify.json").is_file()


def test_never_overwrites(tmp_path):
    base = load_plant()
    tree = yaml.safe_load(config_file("plant.yaml").read_text())
    (tmp_path / "p.yaml").write_text("keep me\n")
    with pytest.raises(ParamError, match=r"a new file, or --overwrite to replace it"):
        write_plant(_ident(base), tree, tmp_path / "p.yaml")
    assert (tmp_path / "p.yaml").read_text() == "keep me\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.yaml"]  # no report, no partial
    # a report left beside it is refused the same way (the pair is written together)
    (tmp_path / "q.identify.json").write_text("{}\n")
    with pytest.raises(ParamError, match=r"q\.identify\.json"):
        write_plant(_ident(base), tree, tmp_path / "q.yaml")
    assert not (tmp_path / "q.yaml").exists()
    out = write_plant(_ident(base), tree, tmp_path / "p.yaml", overwrite=True)
    assert out.read_text().startswith("# Plant") and (tmp_path / "p.identify.json").is_file()
    assert not list(tmp_path.glob("*.partial")) and not list(tmp_path.glob(".*lock"))


def test_a_wide_interval_keeps_the_base_only_where_it_contains_the_base():
    """1.96 σ above half the value (or width) keeps the base value -- the data do not
    determine it -- unless the 95 % interval excludes the base: then the data contradict it."""
    from dataclasses import replace

    from pneu_control.sysid.identify import _taken

    base = load_plant()
    fit = _ident(base).fits["rotary"]
    fit = replace(fit, fit_params=tuple(p for n in fit.names for p in model.AXIS_PARAMS["rotary"] if p.name == n))  # fmt: skip
    # V_m2 3e-6 ± 1.96·5e-5 (q95 1.96) around a base of 1e-5: wide, and the base inside it
    kept: list[str] = []
    plant = _taken(base, fit, kept)
    assert kept == ["rotary.V_m2"] and plant.rotary.V_m2 == base.rotary.V_m2
    assert plant.rotary.J_m == 5.6e-5
    # the same scatter, 5 σ from the base: taken
    far = replace(fit, value=[5.6e-5, 1e-5 + 5 * 5e-5, 0.12])
    kept = []
    plant = _taken(base, far, kept)
    assert kept == [] and plant.rotary.V_m2 == pytest.approx(1e-5 + 5 * 5e-5)
