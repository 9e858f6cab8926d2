"""Late commands (DESIGN §14): a controller that misses ticks, under each late_policy.

A stream of 1 kHz samples in the driver's order (sample k checked, the commands
answering it, the output for tick k+1); the linear controller stops for k ticks and
resumes (or never does), the rotary one goes on. What is written, what is counted,
what trips and when, from the parameters' own values (the defaults unless a test
says otherwise).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from pathlib import Path

import pytest
from pneu_driver.safety import ERROR, WARN, SafetyParams, SafetySupervisor, load_safety_params
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.params.core import ParamError, from_dict

T_NS = 1_000_000
P = SafetyParams()
HOLD, WD, RAMP = round(P.late_hold_ms), round(P.watchdog_ms), round(P.late_ramp_ms)  # periods
U_LIN, U_ROT = 8.0, 6.0  # what the controllers command


class Stream:
    """Plausible samples at 1 kHz into a supervisor; ``x`` [m] can be moved per tick."""

    def __init__(self, params: SafetyParams = P):
        self.sup = SafetySupervisor(params, sample_time_s=1e-3)
        self.k = -1
        self.x = 0.0

    def tick(self, linear: float | None = U_LIN, rotary: float | None = U_ROT):
        """One cycle; ``None``: that controller is late (sends nothing). The tick's output."""
        self.k += 1
        stamp = self.k * T_NS
        wiggle = 10.0 * (self.k % 3)  # live sensors never repeat bit-exactly
        s = SensorSample(
            self.k, stamp, 2.5e5 + wiggle, 2.4e5 - wiggle, 1.8e5 + wiggle,
            self.x + 1e-6 * (self.k % 2), 0.0, 0.0, 0,
        )  # fmt: skip
        self.sup.check_sample(s)
        for axis, u in (("linear", linear), ("rotary", rotary)):
            if u is not None:
                self.sup.command(axis, u, stamp)
        return self.sup.outputs(stamp + T_NS)

    def late(self, n: int, **kw):
        """``n`` ticks without a linear command: the linear outputs."""
        return [self.tick(linear=None, **kw)[0] for _ in range(n)]

    def counts(self, axis: str = "linear") -> tuple[int, int, int]:
        c = self.sup.counters
        return c[f"{axis}.late_ticks"], c[f"{axis}.held_ticks"], c[f"{axis}.ramped_ticks"]

    def errors(self) -> list[tuple[str, str]]:
        return [(e.axis, e.rule) for e in self.sup.events() if e.level == ERROR]


def _policy(name: str, **over) -> SafetyParams:
    return dataclasses.replace(P, late_policy=name, **over)


def test_the_defaults_ride_through_bursts_and_still_trip_a_controller_that_is_gone():
    assert P.late_policy == "hold"
    assert 20 <= HOLD < WD and RAMP <= HOLD  # a ~20-tick burst is held, the watchdog beyond
    assert load_safety_params() == P  # config/safety.yaml says the same


@pytest.mark.parametrize("k", [1, 3, 10, HOLD])
def test_hold_writes_the_last_command_for_a_burst_within_the_hold(k):
    r = Stream()
    r.tick(linear=7.0)
    r.errors()
    assert r.late(k) == [7.0] * k  # the last linear command, held
    assert r.tick() == (U_LIN, U_ROT)  # the controller is back: its command, at once
    assert r.counts() == (k, k, 0)
    assert r.counts("rotary") == (0, 0, 0)  # the other axis was never late
    assert r.errors() == [] and r.sup.status["linear"].state == "OK"


@pytest.mark.parametrize("k", [HOLD + 1, (HOLD + WD) // 2, WD - 1])
def test_a_burst_beyond_the_hold_closes_the_valve_until_the_controller_is_back(k):
    r = Stream()
    r.tick(linear=7.0)
    r.errors()
    out = r.late(k)
    assert out == [7.0] * HOLD + [5.0] * (k - HOLD)  # held, then 5 V (closed centre)
    assert r.tick() == (U_LIN, U_ROT)  # not latched: resumes without an operator
    assert r.counts() == (k, HOLD, 0)
    assert r.errors() == []


@pytest.mark.parametrize("k", [1, RAMP // 2, RAMP, HOLD])
def test_ramp_moves_the_last_command_linearly_to_5_v(k):
    r = Stream(_policy("ramp"))
    r.tick(linear=9.0)
    out = r.late(k)
    # late by m periods: 9 V + (5 - 9) V · m/RAMP, 5 V from m = RAMP on
    want = [9.0 - 4.0 * min(m / RAMP, 1.0) for m in range(1, k + 1)]
    assert out == pytest.approx(want, abs=1e-12)
    assert all(a >= b for a, b in itertools.pairwise(out)) and 5.0 <= min(out)
    assert r.tick() == (U_LIN, U_ROT)
    assert r.counts() == (k, 0, k)
    assert r.errors() == []


def test_ramp_from_below_5_v_and_a_zero_ramp_closes_at_once():
    r = Stream(_policy("ramp", late_ramp_ms=4.0, late_hold_ms=6.0))
    r.tick(linear=1.0)
    assert r.late(8) == pytest.approx([2.0, 3.0, 4.0, 5.0, 5.0, 5.0, 5.0, 5.0])
    assert r.counts() == (8, 0, 6)  # ramped while within the 6 ms hold
    r = Stream(_policy("ramp", late_ramp_ms=0.0))
    r.tick(linear=1.0)
    assert r.late(3) == [5.0] * 3


def test_trip_takes_the_axis_safe_at_the_first_late_tick_latched():
    r = Stream(_policy("trip"))
    r.tick(linear=7.0)
    r.errors()
    assert r.late(1) == [5.0]
    assert r.errors() == [("linear", "late_command")]
    st = r.sup.status["linear"]
    assert st.state == "SAFE" and st.causes == ("late_command",)
    assert r.tick() == (5.0, U_ROT)  # back, but latched until acknowledged
    assert [(e.axis, e.rule) for e in r.sup.events() if e.level == WARN] == [
        ("linear", "late_command")  # the condition is gone
    ]
    ok, msg = r.sup.acknowledge("linear")
    assert ok and "late_command" in msg
    assert r.tick() == (U_LIN, U_ROT)
    # acknowledged while still late: the axis waits (5 V) for a fresh command
    assert r.late(1) == [5.0] and r.errors() == [("linear", "late_command")]
    assert r.sup.acknowledge("linear")[0]
    assert r.sup.status["linear"].causes == ("no_command",)
    assert r.late(3) == [5.0] * 3 and r.errors() == []  # nothing to be late: no trip
    assert r.tick() == (U_LIN, U_ROT)
    assert r.counts() == (2, 0, 0)


@pytest.mark.parametrize("policy", ["hold", "ramp", "trip"])
def test_a_controller_that_never_comes_back_is_latched_by_the_watchdog(policy):
    """Whatever the policy: latched at the WD-th late tick (its command then older than
    watchdog_ms), the valve at 5 V from the first tick beyond the hold on."""
    r = Stream(_policy(policy))
    r.tick(linear=7.0)
    r.errors()
    out = r.late(WD - 1)
    assert ("linear", "watchdog") not in r.errors()
    assert r.sup.status["linear"].state == ("SAFE" if policy == "trip" else "OK")
    assert out[HOLD:] == [5.0] * (WD - 1 - HOLD)
    assert r.late(1) == [5.0]  # the WD-th: watchdog_ms after the last fresh tick
    assert ("linear", "watchdog") in r.errors()
    assert "watchdog" in r.sup.status["linear"].causes
    assert r.late(100) == [5.0] * 100
    late, held, ramped = r.counts()
    assert late == WD - 1  # counted until the watchdog's tick, then gone, not late
    assert (held, ramped) == {"hold": (HOLD, 0), "ramp": (0, HOLD), "trip": (0, 0)}[policy]
    assert r.tick() == (5.0, U_ROT)  # back: still latched
    assert r.sup.acknowledge("linear")[0] and r.tick() == (U_LIN, U_ROT)


def test_the_stroke_soft_limit_acts_on_a_held_command():
    """A late controller's last command extends the piston (8 V): the held output is
    written until the braking way reaches the soft limit, then 5 V (the zone hold); the
    piston driven on to the limit (trapped air) trips the axis, all while the command is
    held and before the watchdog."""
    r = Stream()
    x_hi = r.sup.soft_limits[1]
    r.x = x_hi - 0.041
    for _ in range(11):  # extending at 1 m/s, the controller on time
        r.x += 0.001
        r.tick(linear=8.0)
    r.sup.events()
    out, rules = [], []
    for _ in range(HOLD):  # 1.5 m/s: the braking way v²/(2a) reaches the limit on the way
        r.x += 0.0015
        out.append(r.tick(linear=None)[0])
        rules.append({(e.level, e.rule) for e in r.sup.events()})
    zone = next(i for i, ev in enumerate(rules) if ("WARN", "soft_limit") in ev)
    trip = next(i for i, ev in enumerate(rules) if ("ERROR", "stroke_limit") in ev)
    assert 0 < zone < trip < HOLD
    assert out[:zone] == [8.0] * zone  # held
    assert out[zone:] == [5.0] * (HOLD - zone)  # held at 5 V by the zone, then latched
    assert not any(("ERROR", "watchdog") in ev for ev in rules)
    # every tick late; held (the policy's output, overridden by the zone) until the trip
    assert r.counts() == (HOLD, trip, 0)


# ------------------------------------------------------------------ bad values, one line
@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"late_policy": "pause"}, r"^late_policy: 'pause' refused; allowed: one of hold, ramp, trip$"),
        ({"late_hold_ms": -1.0}, r"^late_hold_ms: -1\.0 refused; allowed: \[0, 1000\] ms"),
        ({"late_hold_ms": 50.0}, r"^late_hold_ms: 50\.0 refused; allowed: \[0, 50\) ms, less than watchdog_ms"),
        ({"watchdog_ms": 10.0}, r"^late_hold_ms: 20\.0 refused; allowed: \[0, 10\) ms, less than watchdog_ms"),
        ({"late_ramp_ms": 25.0}, r"^late_ramp_ms: 25\.0 refused; allowed: \[0, 20\] ms, at most late_hold_ms"),
        ({"late_ramp_ms": math.nan}, r"^late_ramp_ms: nan refused; allowed: \[0, 1000\] ms"),
    ],
)  # fmt: skip
def test_bad_late_values_are_refused_in_one_line(values, message):
    with pytest.raises(ParamError, match=message) as err:
        from_dict(SafetyParams, values, strict=False)
    assert "\n" not in str(err.value)


def test_a_bad_late_value_in_the_file_names_its_line(tmp_path: Path):
    from pneu_msgs_py.params.paths import config_file

    text = config_file("safety.yaml").read_text()
    bad = tmp_path / "safety.yaml"
    bad.write_text(text.replace("late_policy: hold ", "late_policy: wait "))
    with pytest.raises(ParamError, match=r"safety\.yaml:\d+:1: late_policy: 'wait' refused"):
        load_safety_params(bad)
