"""The excitation on the twin: safe (supervisor on, nothing trips), deterministic, logged with its design."""

from __future__ import annotations

import json

import numpy as np
import pytest
from pneu_control.sysid.design import design_from_json
from pneu_control.sysid.excite import excitation_spec, run_excitation
from pneu_control.sysid.record import load_record
from pneu_sim.physics.params import PlantParams


@pytest.fixture(scope="module")
def excited(tmp_path_factory):
    out = tmp_path_factory.mktemp("excite")
    spec = excitation_spec(("linear", "rotary"), PlantParams(), seed=2, level="quick")
    result = run_excitation(spec, out, progress=False, hide_plant=True)
    return spec, result, out / "run.mcap"


def test_stays_inside_the_limits_with_the_supervisor_on(excited):
    spec, result, _ = excited
    assert spec.safety is not None
    assert [e for e in result.safety_events if e.level != "OK"] == []
    x_mm = result.samples["x"] * 1e3
    rpm = result.samples["omega"] * 60 / (2 * np.pi)
    assert np.max(np.abs(x_mm)) < 55.0  # soft limits at ±65 mm less the braking distance
    assert np.max(rpm) < 1450.0  # overspeed trip at 1500 rpm
    # it moved: the stroke and the speed range the design asks for
    assert np.ptp(x_mm) > 70.0 and np.max(rpm) > 900.0


def test_the_bag_carries_the_design_and_seed_not_the_plant(excited):
    from mcap.reader import make_reader  # an independent reader

    spec, _, bag = excited
    with open(bag, "rb") as fh:
        meta = {m.name: m.metadata for m in make_reader(fh).iter_metadata()}
    rec = meta["pneu.excite"]
    assert rec["seed"] == "2"
    designs = json.loads(rec["designs_json"])
    for axis in ("linear", "rotary"):
        assert design_from_json(designs[axis]) == spec.controllers[axis]
    assert json.loads(meta["pneu.run"]["config_json"])["plant"].startswith("hidden")


def test_record_reconstructs_the_voltage_on_the_valves(excited):
    """u[k] of the record (from the commands' stamps) is what the runner held over period k."""
    _, result, bag = excited
    rec = load_record(bag)
    for axis in ("linear", "rotary"):
        assert np.array_equal(rec.u[axis], result.applied[axis])
        assert rec.valid[axis].all()
    assert np.array_equal(rec.y["x"], result.samples["x"])
    assert set(rec.designs) == {"linear", "rotary"}


def test_same_seed_same_bytes(excited, tmp_path):
    spec, result, _ = excited
    again = run_excitation(spec, tmp_path, progress=False, hide_plant=True)
    for k, v in result.samples.items():
        assert np.array_equal(v, again.samples[k])
    for axis in ("linear", "rotary"):
        assert np.array_equal(result.applied[axis], again.applied[axis])
