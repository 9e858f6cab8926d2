"""``pneu bench angle`` on 2 plants: its table and JSON, read back independently.

Each figure of the summary is recomputed here from the encoder samples of the same run
(the compiled loop, re-run through the Python runner: the same bits), so the bench
reports what the twin did; the command's files and its refusals are checked too.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from pneu_control.bench import angle
from pneu_control.cli.main import main
from pneu_control.experiment.runner import run


@pytest.fixture(scope="module")
def small():
    bench = angle.plan_angle_bench(samples=2, seed=3, moves=(90.0,), tasks=False)
    rows = [angle.run_item(item) for item in bench.items]
    return bench, rows, angle.summarise(bench, rows)


def test_move_metrics_on_a_known_trace():
    t = np.arange(6) * 0.1
    th = np.array([0.0, 50.0, 95.0, 91.5, 90.5, 90.2])
    m = angle.move_metrics(t, th, 90.0)
    assert m["final_error_deg"] == pytest.approx(-0.2)
    assert m["settling_s"] == pytest.approx(0.4)  # |e| ≤ 1° from the sample at 0.4 s on
    assert m["overshoot_deg"] == pytest.approx(5.0)
    m = angle.move_metrics(t, -th, -90.0)  # the other way: the same figures
    assert m["overshoot_deg"] == pytest.approx(5.0) and m["settling_s"] == pytest.approx(0.4)
    assert math.isinf(angle.move_metrics(t, th * 0.5, 90.0)["settling_s"])


def test_the_plan_covers_both_plumbings_with_the_task_laws(small):
    bench, rows, _ = small
    # nominal + 2 plants × 2 plumbings × 1 move × supervisor on/off
    assert len(bench.items) == 3 * 2 * 2
    laws = {(r.plumbing, r.algorithm) for r in rows}
    assert laws == {("bidirectional", "pva"), ("paper", "coast")}
    for item in bench.items:
        assert item.spec.plant.rotary.plumbing == item.plumbing
        assert (item.spec.safety is not None) == item.supervisor
        if item.supervisor:
            assert item.spec.safety.rotary_plumbing == item.plumbing


def test_each_row_is_what_the_twin_did(small):
    bench, rows, _ = small
    for item, row in zip(bench.items, rows):
        if item.supervisor:  # (the Python runner: slow; one of each kind suffices)
            continue
        result = run(item.spec)
        th = np.degrees(result.samples["theta"])
        assert row.final_error_deg == pytest.approx(90.0 - th[-1], abs=1e-9)
        assert row.overshoot_deg == pytest.approx(max(0.0, th.max() - 90.0), abs=1e-9)
        out = np.flatnonzero(np.abs(90.0 - th) > 1.0)
        want = result.t[out[-1] + 1] if len(out) and out[-1] < len(th) - 1 else row.settling_s
        assert row.settling_s == pytest.approx(want)


def test_the_summary_counts_the_rows(small):
    _bench, rows, summary = small
    assert summary["samples"] == 2 and summary["seed"] == 3
    for g in summary["moves"]:
        sam = [
            r for r in rows
            if r.sample >= 0 and r.plumbing == g["plumbing"] and r.supervisor == g["supervisor"]
        ]  # fmt: skip
        e_tgt, t_tgt = angle.TARGET[g["plumbing"]]
        met = sum(abs(r.final_error_deg) <= e_tgt and r.settling_s <= t_tgt for r in sam)
        assert g["meets_target"]["k"] == met and g["meets_target"]["n"] == 2
        assert g["within_0p5_deg"]["k"] == sum(abs(r.final_error_deg) <= 0.5 for r in sam)
        assert g["abs_final_error_deg"]["q95"] == pytest.approx(
            max(abs(r.final_error_deg) for r in sam), rel=1e-5
        )
    md = angle.render_markdown(summary)
    assert md.count("\n| bidirectional | pva |") == 2 and md.count("\n| paper | coast |") == 2


def test_the_command_writes_its_table_and_the_same_bytes_again(tmp_path, capsys):
    out = tmp_path / "bench"
    argv = ["bench", "angle", "--samples", "1", "--seed", "5", "--serial", "--no-tasks"]
    assert main([*argv, "--out", str(out)]) == 0
    first = (out / "angle_bench.json").read_bytes()
    summary = json.loads(first)
    assert summary["samples"] == 1 and len(summary["moves"]) == 2 * 2 * len(angle.MOVES_DEG)
    md = (out / "angle_bench.md").read_text()
    assert md.startswith("Angle moves") and "| bidirectional | pva | on | 90° |" in md
    assert main([*argv, "--out", str(out), "--overwrite"]) == 0
    assert (out / "angle_bench.json").read_bytes() == first  # same seed, same bytes
    capsys.readouterr()


@pytest.mark.parametrize(
    ("argv", "field"),
    [
        (["bench", "angle", "--samples", "0"], "--samples"),
        (["bench", "--samples", "3"], "--samples"),
        (["bench", "angle", "--serial", "--workers", "2"], "--workers"),
        (["bench", "angle", "--quick"], "--quick"),
        (["bench", "angle", "--overwrite"], "--overwrite"),
    ],
)
def test_bad_options_are_one_line_before_anything_runs(argv, field, capsys, tmp_path):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and field in err[0] and err[0].startswith("pneu bench: error: ")
