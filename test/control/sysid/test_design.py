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


def test_flow_ladders_step_through_the_openings_from_rest_until_the_guard():
    """The linear design climbs a ladder of valve openings each way (the valve's curve at
    known volume); the exciter holds each step ladder_s, and the guard cuts it."""
    from pneu_control.sysid.exciter import Exciter
    from pneu_msgs_py.contract.samples import SensorSample

    d = design_for("linear", 4, "quick")
    ladders = [s for s in d.segments if s.kind == "pulse" and s.ladder]
    assert len(ladders) == 2 and {math.copysign(1.0, s.u) for s in ladders} == {1.0, -1.0}
    for s in ladders:
        assert len(s.ladder) >= 8 and s.ladder_s > 0.0
        assert all(abs(b) > abs(a) for a, b in zip(s.ladder, s.ladder[1:]))
        assert min(abs(a) for a in s.ladder) < 0.4 and max(abs(a) for a in s.ladder) > 2.0
    assert design_from_json(d.to_json()) == d
    seg = ladders[0]
    ex = Exciter(d)
    x_mm = -40.0 if seg.u > 0 else 40.0  # at rest where the move before it ends
    seen = []
    t = 0.0
    while t < seg.t1_s:
        stamp = round(t * 1e9)
        past = t > seg.t0_s + len(seg.ladder) * seg.ladder_s * 0.5
        x = (x_mm if not past else math.copysign(30.0, seg.u)) * 1e-3  # passes the guard
        u = ex.update(SensorSample(0, stamp, 2e5, 2e5, 1e5, x, 0.0, 0.0, 0))
        if t >= seg.t0_s:
            seen.append(u - 5.0)
        t += 1e-3
    climbed = list(dict.fromkeys(round(v, 9) for v in seen if v != 0.0))  # in order seen
    n = len(climbed)
    assert n >= 3 and climbed == [round(v, 9) for v in seg.ladder[:n]]
    assert seen[-1] == pytest.approx(0.0, abs=1e-9)  # guard tripped: back to 5 V, blocked
