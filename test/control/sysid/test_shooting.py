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
