"""Controller faults on the twin: silent (hung node), NaN commands, a core that raises.

Also: ``pneu analyze`` marks and excludes the fault intervals (and agrees with
the runner's own metrics), and every bag records the safety configuration.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from pneu_control.analysis.run_analysis import analyze
from pneu_control.experiment import runner as runner_mod
from pneu_control.experiment.fault_table import Scenario, run_scenario
from pneu_control.experiment.session import build_spec, execute
from pneu_driver.safety import SafetyParams
from pneu_msgs_py.bag.reader import read_run
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.paths import config_file

F = "start_s=0.5,duration_s=0.5"
K0 = 500
RETUNED = config_file("controllers_retuned.yaml")
P = SafetyParams()
WD, HOLD = round(P.watchdog_ms), round(P.late_hold_ms)  # in 1 ms periods


def test_silent_controllers_trip_the_watchdog_after_watchdog_ms(tmp_path):
    row = run_scenario(
        Scenario(f"controller_silent:axis=both,{F}", ("linear", "rotary"), 1.5),
        tmp_path,
        compare=False,
    )
    # last command answers sample k0-1; at tick k0+WD it is WD+1 ms old (> watchdog_ms)
    assert row.rule == "watchdog" and row.detection_cycles == WD
    assert row.safe_cycles == 0  # 5 V already: the hold ended at tick k0+HOLD+1
    assert row.bag_complete, row.note
    assert row.end_state == "SAFE (latched)"
    res = row.result
    for axis in ("linear", "rotary"):
        # tick k0 writes the answer to k0-1 (fresh), ticks k0+1..k0+HOLD hold it (late by
        # 1..HOLD ms: late_policy hold); from then on 5 V, also after the controller is
        # back (the watchdog latched it until acknowledged)
        assert np.all(res.applied[axis][K0 + HOLD + 1 :] == 5.0)
        assert np.all(res.applied[axis][K0 : K0 + HOLD + 1] == res.axes[axis]["u"][K0 - 1])
        assert np.isnan(res.axes[axis]["u"][K0 : K0 + 500]).all()  # nothing published
        # late by 1 .. WD-1 ms counted (the WD-th is the watchdog's), HOLD of them held
        assert res.safety_counters[f"{axis}.late_ticks"] == WD - 1
        assert res.safety_counters[f"{axis}.held_ticks"] == HOLD
    data = read_run(row.bag)
    cmd = data["/pneu/linear/valve_command"]
    assert len(cmd) == len(res.t) - 500  # the hung controller published nothing


def test_nan_commands_are_never_written(tmp_path):
    row = run_scenario(
        Scenario(f"controller_nan:axis=both,{F}", ("linear", "rotary"), 1.5),
        tmp_path,
        compare=False,
    )
    assert row.rule == "output_sanity" and row.detection_cycles == 0
    assert row.safe_cycles == 1  # the tick at which the NaN would have been written
    assert row.bag_complete, row.note
    res = row.result
    for axis in ("linear", "rotary"):
        assert np.all(np.isfinite(res.applied[axis]))
        assert np.all(res.applied[axis][K0 + 1 :] == 5.0)
    # the bag records what the controller published: NaN
    u = read_run(row.bag)["/pneu/linear/valve_command"]["effort"]
    assert np.isnan(u[K0]) and np.isfinite(u[K0 - 1])


def test_a_controller_that_raises_is_treated_as_crashed(tmp_path, monkeypatch):
    class Crashing(runner_mod.AxisController):
        def update(self, sample):
            if sample.k == 300:
                raise ZeroDivisionError("boom")
            return super().update(sample)

    monkeypatch.setattr(runner_mod, "AxisController", Crashing)
    spec = build_spec(
        axes=("linear",), controller="eso_smc", duration_s=0.6, controllers_file=RETUNED
    )
    res = execute(spec, tmp_path)  # must not raise
    rules = [e.rule for e in res.safety_events]
    assert "controller_exception" in rules and "watchdog" in rules
    # the last command answers sample 299: held until late by late_hold_ms, then 5 V
    assert np.all(res.applied["linear"][300 + HOLD + 1 :] == 5.0)
    assert res.applied["linear"][300 + HOLD] == res.axes["linear"]["u"][299]
    data = read_run(tmp_path / "run.mcap")
    names = [s.name for o in data["/diagnostics"].objects for s in o]
    assert "pneu_runner: safety linear controller_exception" in names


def _spec(faults, include=False, safety=True, duration=1.2):
    return build_spec(
        axes=("linear",),
        controller="eso_smc",
        sets=["reference.kind=sine", "reference.amplitude=20", "reference.frequency_hz=0.25"],
        duration_s=duration,
        controllers_file=RETUNED,
        window_start_s=min(0.2, duration / 2),
        faults=faults,
        include_faults=include,
        safety=safety,
    )


def test_analyze_marks_and_excludes_the_fault_like_the_runner(tmp_path):
    spec = _spec(["controller_silent:axis=linear,start_s=0.6,duration_s=0.2"])
    res = execute(spec, tmp_path)
    an = analyze(tmp_path / "run.mcap")
    kinds = sorted((iv.kind, iv.axis) for iv in an.faults)
    assert kinds == [("injected", "linear"), ("safe", "linear")]
    inj = next(iv for iv in an.faults if iv.kind == "injected")
    assert (inj.start_s, inj.end_s) == (0.6, 0.8)
    safe = next(iv for iv in an.faults if iv.kind == "safe")
    assert safe.start_s == pytest.approx(0.6 + WD * 1e-3) and math.isinf(safe.end_s)
    m, mr = an.metrics["linear"], res.metrics["linear"]
    # window 0.2 s .. end, minus 0.6 s .. end: samples 200..599
    assert m.n_samples == mr.n_samples == 400
    assert (m.e_max, m.rmse) == (mr.e_max, mr.rmse)
    both = analyze(tmp_path / "run.mcap", include_faults=True).metrics["linear"]
    assert both.n_samples == 1200 - 200 - 200  # the silent samples have no controller state
    assert both.e_max >= m.e_max
    intervals = json.loads(
        read_run(tmp_path / "run.mcap").metadata["pneu.fault_intervals"]["intervals_json"]
    )
    assert {d["kind"] for d in intervals} == {"injected", "safe"}


def test_no_fault_no_trip_and_the_supervisor_is_transparent(tmp_path):
    with_sup = execute(_spec([]), tmp_path / "a", bag=False)
    without = execute(_spec([], safety=False), tmp_path / "b", bag=False)
    assert [e.rule for e in with_sup.safety_events] == ["command"]  # 'commands arriving'
    assert with_sup.fault_intervals == []
    np.testing.assert_array_equal(with_sup.samples["x"], without.samples["x"])
    np.testing.assert_array_equal(with_sup.axes["linear"]["u"], without.axes["linear"]["u"])
    assert with_sup.metrics["linear"] == without.metrics["linear"]


def test_every_bag_records_the_safety_configuration(tmp_path):
    execute(_spec([], duration=0.1), tmp_path / "on")
    rec = read_run(tmp_path / "on" / "run.mcap").metadata["pneu.safety"]
    assert rec["enabled"] == "true" and rec["allow_unsafe"] == "false"
    assert json.loads(rec["params_json"])["watchdog_ms"] == P.watchdog_ms
    execute(_spec([], duration=0.1, safety=False), tmp_path / "off")
    assert read_run(tmp_path / "off" / "run.mcap").metadata["pneu.safety"]["enabled"] == "false"


def test_unsafe_safety_file_refused_unless_allowed_then_logged(tmp_path):
    from pneu_msgs_py.params.paths import config_file

    text = config_file("safety.yaml").read_text()
    bad = tmp_path / "safety.yaml"
    default = f"watchdog_ms: {P.watchdog_ms} "
    assert default in text
    bad.write_text(text.replace(default, "watchdog_ms: 2000.0 "))
    with pytest.raises(ParamError, match=r"safety\.yaml:\d+:1: watchdog_ms"):
        build_spec(axes=("linear",), duration_s=0.1, controllers_file=RETUNED, safety_file=bad)
    bad.write_text(
        text.replace(default, "watchdog_ms: 2000.0 ").replace(
            "allow_unsafe: false", "allow_unsafe: true"
        )
    )
    spec = build_spec(axes=("linear",), duration_s=0.1, controllers_file=RETUNED, safety_file=bad)
    res = execute(spec, tmp_path / "run")
    rec = read_run(tmp_path / "run" / "run.mcap").metadata["pneu.safety"]
    assert rec["allow_unsafe"] == "true" and "watchdog_ms=2000" in rec["unsafe_overrides"]
    assert any(e.rule == "allow_unsafe" and e.level == "WARN" for e in res.safety_events)
