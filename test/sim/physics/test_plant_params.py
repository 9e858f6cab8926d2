"""plant.yaml: in sync with the code, every leaf sourced, bad input refused whole."""

import copy
import math

import pytest
import yaml
from pneu_msgs_py.params.core import ParamError, with_updates
from pneu_msgs_py.params.paths import config_file
from pneu_sim.physics.params import PlantParams
from pneu_sim.physics.plant import Plant
from pneu_sim.physics.plant_file import load_plant, params_from_tree


@pytest.fixture(scope="module")
def tree():
    with open(config_file("plant.yaml"), encoding="utf-8") as fh:
        return yaml.safe_load(fh)


def _leaves(node, prefix=""):
    for key, val in node.items():
        if isinstance(val, dict) and "value" in val:
            yield prefix + key, val
        else:
            yield from _leaves(val, prefix + key + ".")


def test_yaml_matches_code_defaults(tree):
    assert load_plant() == PlantParams()
    assert params_from_tree(tree) == PlantParams()


def test_every_leaf_has_unit_and_source(tree):
    leaves = dict(_leaves(tree))
    assert len(leaves) > 60
    for name, leaf in leaves.items():
        assert (
            {"value", "unit", "source"}
            <= set(leaf)
            <= {
                "value",
                "unit",
                "source",
                "range",
                "alternatives",
            }
        ), name
        assert leaf["unit"], name
        assert len(leaf["source"]) > 5, name


def test_supply_is_gauge_setting_plus_atmosphere():
    p = PlantParams()
    assert p.supply.p_s_linear - p.ambient.p_a == pytest.approx(0.2e6)
    assert p.supply.p_s_rotary - p.ambient.p_a == pytest.approx(0.4e6)


def _refused(tree, path, value, *, delete=False):
    t = copy.deepcopy(tree)
    node = t
    parts = path.split(".")
    for part in parts[:-1]:
        node = node[part]
    if delete:
        del node[parts[-1]]
    else:
        node[parts[-1]] = value
    with pytest.raises(ParamError) as err:
        params_from_tree(t)
    return str(err.value)


def test_missing_key_named(tree):
    msg = _refused(tree, "linear.M", None, delete=True)
    assert msg.startswith("linear.M:") and "required" in msg


def test_missing_group_named(tree):
    msg = _refused(tree, "rotary", None, delete=True)
    assert msg.startswith("rotary:") and "required" in msg


def test_unknown_key_named(tree):
    msg = _refused(tree, "linear.mass", {"value": 1.0, "unit": "kg", "source": "x"})
    assert msg.startswith("linear.mass:") and "no such parameter" in msg


def test_wrong_type_named(tree):
    msg = _refused(tree, "linear.M", {"value": "heavy", "unit": "kg", "source": "x"})
    assert msg.startswith("linear.M: 'heavy'") and "a number" in msg
    msg = _refused(tree, "rotary.n_vanes", {"value": 4.5, "unit": "-", "source": "x"})
    assert msg.startswith("rotary.n_vanes: 4.5") and "integer" in msg


@pytest.mark.parametrize(
    ("path", "value", "unit"),
    [
        ("linear.V_1d", 0.0, "m^3"),
        ("linear.V_2d", -1e-6, "m^3"),
        ("linear.A_c1", 0.0, "m^2"),
        ("rotary.V_m1", 0.0, "m^3"),
        ("rotary.A_ex", -1.0, "m^2"),
    ],
)
def test_non_positive_volume_or_area(tree, path, value, unit):
    msg = _refused(tree, path, {"value": value, "unit": unit, "source": "x"})
    assert msg.startswith(f"{path}: {value!r} refused")
    assert "(0, " in msg and unit in msg


def test_out_of_physical_range(tree):
    msg = _refused(tree, "valve_linear.b", {"value": 0.9, "unit": "-", "source": "x"})
    assert msg.startswith("valve_linear.b: 0.9 refused") and "0.528" in msg
    msg = _refused(tree, "ambient.n_poly", {"value": 1.6, "unit": "-", "source": "x"})
    assert msg.startswith("ambient.n_poly: 1.6") and "[1, 1.4]" in msg
    msg = _refused(tree, "linear.A_c2", {"value": 9e-4, "unit": "m^2", "source": "x"})
    assert msg.startswith("linear.A_c2: 0.0009") and "A_c1" in msg
    msg = _refused(tree, "supply.p_s_linear", {"value": 1.0e5, "unit": "Pa", "source": "x"})
    assert "supply.p_s_linear" in msg


def test_unit_mismatch_and_bare_value(tree):
    msg = _refused(tree, "linear.M", {"value": 280.0, "unit": "g", "source": "x"})
    assert msg.startswith("linear.M.unit: 'g'") and "'kg'" in msg
    msg = _refused(tree, "linear.M", 0.28)
    assert msg.startswith("linear.M: 0.28") and "leaf" in msg
    msg = _refused(tree, "linear.M", {"value": 0.28, "unit": "kg", "source": ""})
    assert msg.startswith("linear.M.source")


def test_load_plant_bad_file_refused_whole(tmp_path, tree):
    t = copy.deepcopy(tree)
    t["rotary"]["J_m"]["value"] = math.inf
    path = tmp_path / "plant.yaml"
    path.write_text(yaml.safe_dump(t), encoding="utf-8")
    with pytest.raises(ParamError, match=r"plant\.yaml:\d+:\d+: rotary\.J_m: inf refused"):
        load_plant(path)


def test_set_params_bad_update_keeps_old():
    plant = Plant(PlantParams())
    before = plant.params
    with pytest.raises(ParamError, match=r"^linear\.M: -1"):
        plant.set_params(with_updates(before, {"linear.M": -1.0}))
    assert plant.params is before
    with pytest.raises(ParamError, match=r"^sim\.T"):
        plant.set_params(with_updates(before, {"sim.T": 2e-3}))
    assert plant.params is before
