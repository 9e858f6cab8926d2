"""Excitation designs: what each axis runs, within the time budget, serialised into the bag."""

from __future__ import annotations

import math

import pytest
from pneu_control.sysid.design import design_for, design_from_json
from pneu_msgs_py.params.core import ParamError


@pytest.mark.parametrize("axis", ["linear", "rotary"])
def test_full_design_fits_two_minutes_and_has_every_kind(axis):
    d = design_for(axis, 0, "full")
    assert d.duration_s <= 120.0
    kinds = {s.kind for s in d.segments}
    refs = {s.ref["kind"] for s in d.segments if s.kind == "closed"}
    assert kinds == {"hold", "pulse", "closed"}
    assert {"move", "ramp", "chirp", "prbs"} <= refs
    # steps of several sizes in both directions
    steps = {round(s.u, 2) for s in d.segments if s.kind == "pulse" and s.u != 0.0}
    assert len({abs(u) for u in steps}) >= 3 and min(steps) < 0 < max(steps)
    # every open-loop step that could run away has a guard
    for s in d.segments:
        if s.kind == "pulse" and s.u != 0.0:
            assert math.isfinite(s.guard_hi) or math.isfinite(s.guard_lo)
    # the schedule is contiguous
    for a, b in zip(d.segments[:-1], d.segments[1:]):
        assert b.t0_s == pytest.approx(a.t1_s)


@pytest.mark.parametrize("axis", ["linear", "rotary"])
def test_quick_design_is_short(axis):
    assert design_for(axis, 3, "quick").duration_s <= 60.0


def test_json_round_trip_and_seeds():
    d = design_for("rotary", 7, "full")
    assert design_from_json(d.to_json()) == d
    assert design_for("rotary", 7, "full") == d  # deterministic
    other = design_for("rotary", 8, "full")
    assert [s.u for s in other.segments] != [s.u for s in d.segments]  # another experiment


def test_bad_arguments_name_the_field():
    with pytest.raises(ParamError, match="axis"):
        design_for("spindle", 0)
    with pytest.raises(ParamError, match="level"):
        design_for("linear", 0, "long")
    with pytest.raises(ParamError, match="seed"):
        design_for("linear", -1)
