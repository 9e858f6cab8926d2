"""Plant samples: seeded, stratified, inside the ranges, applied to the plant as one set."""

import numpy as np
import pytest
from pneu_control.sweep.sampling import draw_points, factors_of, plant_of, unit_design
from pneu_msgs_py.params.core import ParamError, flatten
from pneu_sim.physics.plant_file import load_plant_file
from pneu_sim.physics.ranges import PlantRanges


@pytest.fixture(scope="module")
def plant_and_factors():
    nominal, ranges = load_plant_file()
    return nominal, ranges, factors_of(ranges, nominal)


def test_factors_follow_the_plant_file(plant_and_factors):
    nominal, ranges, factors = plant_and_factors
    cont = [f for f in factors if not f.discrete]
    disc = [f for f in factors if f.discrete]
    assert [f.name for f in cont] == list(ranges.ranges)
    assert all((f.lo, f.hi) == ranges.ranges[f.name] for f in cont)
    # both supplies move together: one factor, gauge or absolute
    assert len(disc) == 1
    (sup,) = disc
    assert sup.name == "supply[gauge|absolute]"
    assert sup.keys == ("supply.p_s_linear", "supply.p_s_rotary")
    assert sup.values == ((301325.0, 501325.0), (200000.0, 400000.0))
    order = list(flatten(nominal))
    assert [order.index(f.keys[0]) for f in factors] == sorted(
        order.index(f.keys[0]) for f in factors
    )


def test_same_seed_same_points_other_seed_other(plant_and_factors):
    _, _, factors = plant_and_factors
    a = draw_points(factors, 16, seed=3)
    assert a == draw_points(factors, 16, seed=3)
    assert a != draw_points(factors, 16, seed=4)
    s = draw_points(factors, 16, seed=3, method="sobol")
    assert s == draw_points(factors, 16, seed=3, method="sobol") and s != a


@pytest.mark.parametrize("n", [10, 37])
def test_latin_hypercube_one_sample_per_stratum(plant_and_factors, n):
    _, _, factors = plant_and_factors
    pts = draw_points(factors, n, seed=11)
    for f in factors:
        if f.discrete:
            labels = [p[f.name] for p in pts]
            counts = [labels.count(lab) for lab in f.labels]
            assert max(counts) - min(counts) <= 1, counts  # LHS balances the labels too
            continue
        v = np.array([p[f.name] for p in pts])
        assert np.all((v >= f.lo) & (v <= f.hi))
        strata = np.floor((v - f.lo) / (f.hi - f.lo) * n).astype(int)
        assert sorted(strata) == list(range(n)), f.name


def test_sobol_points_inside_ranges_and_not_a_power_of_two(plant_and_factors):
    _, _, factors = plant_and_factors
    u = unit_design(len(factors), 12, seed=0, method="sobol")  # no warning: base-2 draw, cut
    assert u.shape == (12, len(factors)) and np.all((u >= 0) & (u < 1))


def test_plant_of_sets_every_factor(plant_and_factors):
    nominal, _, factors = plant_and_factors
    pts = draw_points(factors, 4, seed=1)
    for p in pts:
        plant = plant_of(nominal, factors, p)
        flat = flatten(plant)
        for f in factors:
            for key, value in f.updates(p[f.name]).items():
                assert flat[key] == value
        if p["supply[gauge|absolute]"] == "absolute":
            assert plant.supply.p_s_linear == 0.2e6 and plant.supply.p_s_rotary == 0.4e6
        else:
            assert plant.supply.p_s_linear == pytest.approx(0.2e6 + plant.ambient.p_a)
        untouched = set(flat) - {k for f in factors for k in f.keys}
        assert all(flat[k] == flatten(nominal)[k] for k in untouched)


def test_a_combination_the_plant_refuses_is_named(plant_and_factors):
    nominal, _, _ = plant_and_factors
    ranges = PlantRanges(ranges={"rotary.r_m": (0.0165, 0.0195)})
    factors = factors_of(ranges, nominal)
    with pytest.raises(ParamError, match=r"^rotary\.r_m: .*sample of the ranges"):
        plant_of(nominal, factors, {"rotary.r_m": 0.0192})


@pytest.mark.parametrize(
    ("kw", "msg"),
    [({"n": 0}, r"^samples: 0 refused"), ({"method": "grid"}, r"^sampler: 'grid' refused")],
)
def test_bad_design_options_refused(kw, msg):
    args = {"d": 3, "n": 4, "seed": 0, "method": "lhs"} | kw
    with pytest.raises(ValueError, match=msg):
        unit_design(**args)
