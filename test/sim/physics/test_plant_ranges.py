"""plant.yaml ranges and alternatives: every estimate carries one, checked like the rest,
optional (old files load), written back by the dumper (DESIGN §11, issue 13)."""

import copy

import pytest
import yaml
from pneu_msgs_py.params.core import ParamError, flatten, with_updates
from pneu_msgs_py.params.paths import config_file
from pneu_sim.physics.params import PlantParams
from pneu_sim.physics.plant_file import (
    dump_plant_yaml,
    load_plant,
    load_plant_file,
    plant_from_tree,
)
from pneu_sim.physics.ranges import PlantRanges, table_ranges


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


def test_config_file_is_the_dump_of_the_table():
    assert config_file("plant.yaml").read_text(encoding="utf-8") == dump_plant_yaml()


def test_every_estimate_carries_a_range_holding_its_value(tree):
    leaves = dict(_leaves(tree))
    estimated = [n for n, leaf in leaves.items() if "estimated" in leaf["source"].lower()]
    assert len(estimated) >= 20
    for name in estimated:
        leaf = leaves[name]
        assert "range" in leaf or "alternatives" in leaf, f"{name}: estimated without a range"
        if "range" in leaf:
            lo, hi = leaf["range"]
            assert lo <= leaf["value"] <= hi and lo < hi, name
            assert "range" in leaf["source"], f"{name}: the source does not give the range's reason"


def test_datasheet_tolerances_and_the_supply_reading(tree):
    p, unc = load_plant_file()
    # Festo MPYE nominal flow ±10 %, J_m ±50 %, n from isothermal to adiabatic
    lo, hi = unc.ranges["valve_linear.Q_n"]
    assert lo == pytest.approx(0.9 * p.valve_linear.Q_n, rel=1e-3)
    assert hi == pytest.approx(1.1 * p.valve_linear.Q_n, rel=1e-3)
    assert unc.ranges["rotary.J_m"] == pytest.approx((0.5 * 3.5e-5, 1.5 * 3.5e-5))
    assert unc.ranges["ambient.n_poly"] == (1.0, 1.4)
    # the discrete factor: the paper's 0.2 / 0.4 MPa as gauge (nominal) or absolute
    for key, mpa in (("supply.p_s_linear", 0.2e6), ("supply.p_s_rotary", 0.4e6)):
        alts = dict(unc.alternatives[key])
        assert alts == {"gauge": mpa + p.ambient.p_a, "absolute": mpa}
        assert flatten(p)[key] == alts["gauge"]
    # facts without a stated tolerance stay fixed
    for key in ("ambient.R", "ambient.gamma", "linear.L", "sim.T", "sensors.daq.ai_bits"):
        assert key not in unc.ranges and key not in unc.alternatives


def test_old_file_without_ranges_still_loads(tree, tmp_path):
    t = copy.deepcopy(tree)
    for _, leaf in _leaves(t):
        leaf.pop("range", None)
        leaf.pop("alternatives", None)
    path = tmp_path / "plant.yaml"
    path.write_text(yaml.safe_dump(t, allow_unicode=True), encoding="utf-8")
    p, unc = load_plant_file(path)
    assert p == PlantParams() and load_plant(path) == p
    assert not unc and unc == PlantRanges()


def test_dump_load_round_trip_keeps_given_ranges(tmp_path):
    p = with_updates(PlantParams(), {"rotary.J_m": 4e-5})
    unc = PlantRanges(
        ranges={"rotary.J_m": (3.5e-5, 4.5e-5)},
        alternatives={"supply.p_s_linear": (("gauge", 301325.0), ("absolute", 200000.0))},
    )
    path = tmp_path / "identified.yaml"
    path.write_text(dump_plant_yaml(p, unc), encoding="utf-8")
    p2, unc2 = load_plant_file(path)
    assert p2 == p and unc2 == unc


def test_identified_value_outside_the_band_moves_the_band():
    # J_m identified at 8e-5 (outside 1.75e-5..5.25e-5): the ±50 % band follows it
    p = with_updates(PlantParams(), {"rotary.J_m": 8e-5, "linear.M": 0.27})
    r = table_ranges(p)
    assert r.ranges["rotary.J_m"] == pytest.approx((4e-5, 12e-5))
    assert r.ranges["linear.M"] == table_ranges().ranges["linear.M"]  # inside: kept
    # ... and the dump of such a plant loads back
    p2, r2 = plant_from_tree(yaml.safe_load(dump_plant_yaml(p)))
    assert p2 == p and r2 == r


def _refused(tree, path, **leaf_updates):
    t = copy.deepcopy(tree)
    node = t
    for part in path.split("."):
        node = node[part]
    node.update(leaf_updates)
    with pytest.raises(ParamError) as err:
        plant_from_tree(t)
    return str(err.value)


@pytest.mark.parametrize(
    ("path", "update", "starts", "says"),
    [
        ("rotary.J_m", {"range": [4e-5, 5e-5]}, "rotary.J_m.range:", "holding the value 3.5e-05"),
        ("rotary.J_m", {"range": [5e-5, 1e-5]}, "rotary.J_m.range:", "lo < hi"),
        ("rotary.J_m", {"range": [3e-5]}, "rotary.J_m.range:", "[lo, hi]"),
        ("rotary.J_m", {"range": ["a", 1e-4]}, "rotary.J_m.range:", "[lo, hi]"),
        ("ambient.n_poly", {"range": [0.9, 1.4]}, "ambient.n_poly.range:", "[1, 1.4]"),
        ("linear.V_1d", {"range": [0.0, 2e-5]}, "linear.V_1d.range:", "(0, 0.001]"),
        ("rotary.n_vanes", {"range": [3, 5]}, "rotary.n_vanes.range:", "only real-valued"),
        (
            "supply.p_s_linear",
            {"alternatives": {"gauge": 301325.0, "absolute": 210000.0}, "value": 250000.0},
            "supply.p_s_linear.alternatives:",
            "one of them the value",
        ),
        (
            "supply.p_s_linear",
            {"alternatives": {"gauge": 301325.0}},
            "supply.p_s_linear.alternatives:",
            ">= 2 distinct",
        ),
        (
            "supply.p_s_linear",
            {"alternatives": {"gauge": 301325.0, "absolute": 1.0e5}},
            "supply.p_s_linear.alternatives.absolute:",
            "[120000, 1.1e+06]",
        ),
        ("linear.M", {"rnage": [0.2, 0.3]}, "linear.M:", "leaf keys value, unit, source, range"),
    ],
)
def test_bad_range_refused_naming_the_field(tree, path, update, starts, says):
    msg = _refused(tree, path, **update)
    assert msg.startswith(starts), msg
    assert says in msg, msg
    assert "\n" not in msg


def test_a_bad_value_is_named_before_its_range(tree):
    msg = _refused(tree, "linear.V_1d", value=0.0)
    assert msg.startswith("linear.V_1d: 0.0 refused; allowed: (0, 0.001] m^3"), msg
    msg = _refused(tree, "supply.p_s_rotary", value=5e4)
    assert msg.startswith("supply.p_s_rotary: 50000.0 refused"), msg
