"""Task programs: what a segment means (targets, durations, conditions), and bad programs refused
in one line naming the segment and the field, before anything runs."""

from __future__ import annotations

import math

import pytest
from pneu_control.task.program import DEG_S_PER_RPM, parse_task
from pneu_driver.safety import SafetyParams
from pneu_msgs_py.params.core import ParamError


def _task(*segments, **top):
    return {"name": "t", "segments": list(segments), **top}


def test_targets_chain_and_durations_follow_the_speeds():
    p = parse_task(
        _task(
            {"move": {"to_mm": 40.0, "speed_mm_s": 40.0}},
            {"rotate": {"by_deg": 90.0, "speed_rpm": 60.0}},
            {"rotate": {"turns": 2.0, "duration_s": 1.5}},
            {"spin": {"speed_rpm": 300.0, "duration_s": 2.0}},
            {"screw": {"pitch_mm": -1.5, "turns": 3.0, "rate_turns_s": 1.0}},
            {"dwell": {"duration_s": 0.5}},
        ),
        x0_m=0.01,
    )
    s = p.segments
    assert s[0].x_start == 0.01 and s[0].x_end == pytest.approx(0.04)
    assert s[0].duration_s == pytest.approx(2 * 30.0 / 40.0)  # smooth step: peak speed 2Δ/D
    assert s[1].theta_end == pytest.approx(math.radians(90.0))
    assert s[1].duration_s == pytest.approx(2 * 90.0 / (60.0 * DEG_S_PER_RPM))
    assert s[2].theta_end == pytest.approx(math.radians(90.0 + 720.0))
    assert s[3].theta_end == pytest.approx(
        s[2].theta_end + math.radians(300 * 6.0 * (2.0 - 0.25))
    )  # ramps
    assert s[4].x_end == pytest.approx(0.04 - 0.0045)  # pitch x turns, retracting
    assert s[4].theta_end == pytest.approx(s[3].theta_end + 6 * math.pi)
    assert s[5].x_start == s[4].x_end and s[5].duration_s == 0.5
    # default conditions: settled for motions, the planned time for spin and dwell
    assert [x.until["kind"] for x in s] == [
        "settled",
        "settled",
        "settled",
        "time",
        "settled",
        "time",
    ]
    assert all(x.timeout_s >= x.duration_s for x in s)
    assert p.planned_s == pytest.approx(sum(x.timeout_s for x in s))


def test_conditions_are_parsed_in_si():
    p = parse_task(
        _task(
            {
                "wait": {},
                "until": {"pressure": {"sensor": "p_c1", "above_kpa": 400}},
                "timeout_s": 2,
            },
            {"wait": {}, "until": {"force": {"below_n": -20}}, "on_timeout": "continue"},
        )
    )
    a, b = p.segments
    assert a.until == {"kind": "pressure", "sensor": "p_c1", "side": "above", "value": 400e3}
    assert b.until == {"kind": "force", "side": "below", "value": -20.0}
    assert b.on_timeout == "continue"


@pytest.mark.parametrize(
    ("segments", "top", "where", "allowed"),
    [
        ([{"move": {"to_mm": 80.0, "speed_mm_s": 10.0}}], {}, "segments[0].move", "soft limits"),
        ([{"move": {"by_mm": 5.0}}], {}, "segments[0].move", "speed_mm_s or duration_s"),
        (
            [{"move": {"to_mm": 5.0, "speed_mm_s": 5.0, "duration_s": 1.0}}],
            {},
            "segments[0].move",
            "one of",
        ),
        (
            [{"rotate": {"by_deg": -90.0, "speed_rpm": 60.0}}],
            {},
            "segments[0].rotate.by_deg",
            "drives one way",
        ),
        (
            [{"spin": {"speed_rpm": 2000.0, "duration_s": 1.0}}],
            {"plumbing": "bidirectional"},
            "segments[0].spin.speed_rpm",
            "max_speed_rpm",
        ),
        ([{"dwell": {"duration_s": 1.0}}, {"jump": {}}], {}, "segments[1]", "exactly one of"),
        (
            [{"move": {"to_mm": 10.0, "speed_mm_s": 1.0}, "timeout_s": 3.0}],
            {},
            "segments[0].timeout_s",
            "the motion it bounds",
        ),
        (
            [{"move": {"to_mm": 1.0, "speed_mm_s": 1.0}, "until": {"settled": {"tol_mm": -1}}}],
            {},
            "segments[0].until.settled.tol_mm",
            "(0, 150) mm (narrower than the stroke)",
        ),
        ([{"wait": {}}], {}, "segments[0].until", "a condition"),
        (
            [{"wait": {}, "until": {"pressure": {"sensor": "p_x", "above_kpa": 1}}}],
            {},
            "segments[0].until.pressure.sensor",
            "p_c1",
        ),
        ([{"dwell": {"duration_s": 1.0}, "colour": "red"}], {}, "segments[0].colour", "one of"),
        (
            [{"rotate": {"turns": 3.0, "speed_rpm": 60.0}}],
            {"plumbing": "bidirectional", "limits": {"angle_max_deg": 720.0}},
            "segments[0].rotate",
            "inside the soft limits [-inf, 690]°",
        ),
        (
            [
                {"rotate": {"by_deg": 700.0, "speed_rpm": 60.0}}
            ],  # inside the range, not the soft limits
            {
                "plumbing": "bidirectional",
                "limits": {"angle_min_deg": -720.0, "angle_max_deg": 720.0},
            },
            "segments[0].rotate",
            "inside the soft limits [-690, 690]°",
        ),
        (
            [{"dwell": {"duration_s": 1.0}}],
            {"limits": {"angle_min_deg": -20.0, "angle_max_deg": 20.0}},
            "limits",
            "wider than 2 × angle_margin_deg (60°",
        ),
        ([{"screw": {"pitch_mm": 1.0, "turns": 2.0}}], {}, "segments[0].screw", "rate_turns_s"),
        ([], {}, "segments", "non-empty"),
        (
            [{"dwell": {"duration_s": 1.0}}],
            {"plumbing": "both"},
            "plumbing",
            "paper or bidirectional",
        ),
    ],
)
def test_bad_programs_are_refused_in_one_line(segments, top, where, allowed):
    with pytest.raises(ParamError) as err:
        parse_task(_task(*segments, **top), safety=SafetyParams())
    text = str(err.value)
    assert "\n" not in text
    assert err.value.key == where, text
    assert allowed in text, text


def test_bidirectional_plumbing_turns_both_ways():
    p = parse_task(
        _task({"rotate": {"by_deg": -90.0, "speed_rpm": 60.0}}, plumbing="bidirectional")
    )
    assert p.segments[0].theta_end == pytest.approx(-math.pi / 2)


def test_the_tools_range_is_the_tasks_limits_within_the_supervisors():
    import dataclasses

    sp = dataclasses.replace(
        SafetyParams(), angle_limits=True, angle_min_deg=-400.0, angle_max_deg=400.0
    )
    p = parse_task(
        _task(
            {"dwell": {"duration_s": 1.0}},
            limits={"angle_min_deg": -1000.0, "angle_max_deg": 200.0},
        ),
        safety=sp,
    )
    assert p.angle_limits_deg == (-400.0, 200.0)
    # the supervisor's own range applies to a task without limits as well
    with pytest.raises(ParamError, match=r"inside the soft limits \[-370, 370\]"):
        parse_task(
            _task({"rotate": {"by_deg": 380.0, "speed_rpm": 60.0}}, plumbing="bidirectional"),
            safety=sp,
        )
    assert (
        parse_task(_task({"dwell": {"duration_s": 1.0}}), safety=SafetyParams()).angle_limits_deg
        is None
    )
