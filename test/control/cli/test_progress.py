"""Progress bars: count, rate and time left on a terminal; nothing off a terminal.

The commands are run with stderr replaced by a text stream that says it is (or
is not) a terminal; ``pneu paper`` and ``pneu tune`` run on shortened
experiments / grids so that the bar's total can be checked against the runs made.
"""

from __future__ import annotations

import io
import re
from dataclasses import replace

import pytest
import yaml
from pneu_control.cli import paper as paper_cli
from pneu_control.cli.main import main
from pneu_control.cli.progress import counted, progress_bar, progress_to
from pneu_control.experiment import tuning
from pneu_control.experiment.catalog import experiment_by_id


class Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_bar_shows_count_rate_and_time_left_on_a_terminal():
    out = Tty()
    bar = progress_bar(3, "work", unit="run", file=out)
    double = counted(lambda x: 2 * x, bar)
    assert [double(i) for i in range(3)] == [0, 2, 4]
    bar.close()
    last = out.getvalue().split("\r")[-1]
    # e.g. "work: 100%|██████████| 3/3 [00:00<00:00, 3.1e+03run/s]"
    assert re.search(r"work: 100%.*3/3 \[\d\d:\d\d<\d\d:\d\d, .*run/s\]", last), last


def test_progress_callback_moves_the_bar_to_done_and_takes_a_new_total():
    out = Tty()
    bar = progress_bar(1, "sweep", unit="run", file=out)
    report = progress_to(bar, "sweep")
    for done in (1, 3, 4):  # runs finish in batches; the total is learnt from the first call
        report(done, 4)
    assert (bar.n, bar.total) == (4, 4)
    bar.close()
    assert "4/4" in out.getvalue().split("\r")[-1]


def test_progress_callback_off_a_terminal_prints_a_line_at_the_end(capsys):
    bar = progress_bar(5, "sweep", unit="run", file=io.StringIO())
    report = progress_to(bar, "sweep", every_s=1e9)
    for done in range(1, 6):
        report(done, 5)
    bar.close()
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and re.fullmatch(r"  sweep: 5/5 runs, \d+ s", lines[0]), lines


def test_bar_is_silent_off_a_terminal():
    out = io.StringIO()
    bar = progress_bar(3, "work", file=out)
    counted(lambda: None, bar)()
    bar.write("a line still prints", file=out)
    bar.close()
    assert bar.disable and out.getvalue() == "a line still prints\n"


def test_pneu_paper_counts_every_run_and_seed(tmp_path, monkeypatch):
    short = replace(experiment_by_id("smooth_step_eq38"), duration_s=0.3)
    monkeypatch.setattr(paper_cli, "experiment_by_id", lambda _id: short)
    err = Tty()
    monkeypatch.setattr("sys.stderr", err)
    argv = ["paper", "--out", str(tmp_path), "--only", "x", "--no-plots", "--seeds", "2"]
    assert main(argv) == 0
    n = len(paper_cli.paper.runs_for(short)) * 2  # 3 (controller, gains) rows x 2 seeds
    bars = re.findall(r"pneu paper: +\d+%.*?(\d+)/(\d+) \[", err.getvalue())
    assert bars and bars[-1] == (str(n), str(n))


def test_pneu_tune_counts_every_grid_point(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(tuning, "identify_b0", lambda axis, plant: 1000.0)
    small = tuning.grid_for
    monkeypatch.setattr(tuning, "grid_for", lambda alg, axis, paper: small(alg, axis, paper)[:2])
    calls = []

    def make_score(axis, plant, controllers_file):
        return lambda overrides: calls.append((axis, overrides["algorithm"])) or 1.0

    monkeypatch.setattr(tuning, "make_score", make_score)
    err = Tty()
    monkeypatch.setattr("sys.stderr", err)
    out = tmp_path / "retuned.yaml"
    assert main(["tune", "--out", str(out), "--axis", "linear", "--algorithm", "pid"]) == 0
    assert calls == [("linear", "pid")] * 2
    bars = re.findall(r"pneu tune: +\d+%.*?(\d+)/(\d+) \[", err.getvalue())
    assert bars[-1] == ("2", "2")
    assert "linear: identified b0 = 1000" in err.getvalue()
    assert "linear_controller" in yaml.safe_load(out.read_text())


@pytest.mark.parametrize("command", ["paper", "tune"])
def test_commands_print_no_bar_into_a_pipe(command, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(tuning, "identify_b0", lambda axis, plant: 1000.0)
    monkeypatch.setattr(tuning, "make_score", lambda *a: lambda o: 1.0)
    short = replace(experiment_by_id("smooth_step_eq38"), duration_s=0.2)
    monkeypatch.setattr(paper_cli, "experiment_by_id", lambda _id: short)
    argv = {
        "paper": ["paper", "--out", str(tmp_path), "--only", "x", "--no-plots", "--seeds", "1"],
        "tune": ["tune", "--out", str(tmp_path / "t.yaml"), "--axis", "rotary"],
    }[command]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "\r" not in captured.err + captured.out and "%|" not in captured.err
