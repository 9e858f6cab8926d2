"""Nothing lost, nothing unclear: the run lifecycle through the ``pneu`` command.

Each refusal is exit code 2 with one stderr line naming the option, and the
files already there are untouched (compared byte for byte).
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest
from mcap_ros2.reader import read_ros2_messages
from pneu_control.cli.main import main
from pneu_msgs_py.bag.reader import read_run

_spec = importlib.util.spec_from_file_location("_proc", Path(__file__).with_name("_proc.py"))
P = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(P)

SHORT = ["--axis", "linear", "--controller", "pid", "--duration", "0.3", "--window-start", "0.1"]


def refused(capsys, argv, *needles) -> str:
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for n in needles:
        assert n in err[0], err[0]
    return err[0]


def snapshot(d: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(d.iterdir())}


@pytest.fixture(scope="module")
def done(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "done"
    assert main(["run", *SHORT, "--out", str(out)]) == 0
    return out


def test_a_run_directory_is_never_reused_silently(done, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", *SHORT, "--out", str(out)]) == 0
    before = snapshot(out)
    assert sorted(before) == ["metrics.json", "run.mcap", "timeseries.npz"]
    refused(capsys, ["run", *SHORT, "--out", str(out)], "--out", "--overwrite", "run.mcap")
    # bad input into an existing run: refused before anything is touched
    refused(capsys, ["run", *SHORT, "--seed", "-1", "--out", str(out), "--overwrite"], "--seed")
    refused(capsys, ["run", *SHORT[:4], "--duration", "0.001", "--out", str(out)], "--out")
    assert snapshot(out) == before
    # --overwrite with --no-bag: the old bag goes too (analyze would report the wrong run)
    assert main(["run", *SHORT, "--seed", "4", "--no-bag", "--out", str(out), "--overwrite"]) == 0
    assert sorted(snapshot(out)) == ["metrics.json", "timeseries.npz"]
    assert json.loads((out / "metrics.json").read_text())["seed"] == 4


def test_an_output_is_never_an_input(done, capsys):
    bag = done / "run.mcap"
    before = bag.read_bytes()
    refused(capsys, ["replay", str(bag), "--out", str(bag)], "--out", "inputs")
    refused(capsys, ["replay", str(bag), "--out", str(bag), "--overwrite"], "--out", "inputs")
    refused(capsys, ["plot", str(bag), "--out", str(bag), "--overwrite"], "--out")
    refused(capsys, ["recover", str(bag), "--out", str(bag), "--overwrite"], "--out", "inputs")
    assert bag.read_bytes() == before


def test_plot_writes_the_file_it_names_and_refuses_a_directory(done, tmp_path, capsys):
    refused(capsys, ["plot", str(done / "run.mcap"), "--out", str(tmp_path)], "--out")
    refused(capsys, ["plot", str(done / "run.mcap"), "--out", str(tmp_path / "fig")], ".png")
    png = tmp_path / "fig.png"
    assert main(["plot", str(done / "run.mcap"), "--out", str(png)]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {png}"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    refused(capsys, ["plot", str(done / "run.mcap"), "--out", str(png)], "--overwrite")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig.png"]


def test_two_runs_into_one_directory_at_once_cannot_both_proceed(tmp_path):
    out = tmp_path / "shared"
    argv = ["run", *SHORT[:-4], "--duration", "2", "--out", str(out)]
    procs = [P.start(*argv) for _ in range(2)]
    results = [P.finish(p) for p in procs]
    codes = sorted(rc for rc, _, _ in results)
    assert codes == [0, 2], results
    loser = next(err for rc, _, err in results if rc == 2)
    assert "--out" in loser and "Traceback" not in loser
    n = sum(1 for _ in read_ros2_messages(str(out / "run.mcap")))
    assert n == read_run(out / "run.mcap").message_count > 0


def test_safety_stop_is_exit_3_and_a_reference_outside_the_stroke_is_refused(tmp_path, capsys):
    # the command: refused before the run (it drove the piston into the end stop)
    refused(
        capsys,
        ["run", "--axis", "linear", "--reference", "sine:amplitude=500,frequency_hz=0.25",
         "--out", str(tmp_path / "a")],
        "--reference", "soft limits [-65, 65] mm", "500 mm",
    )  # fmt: skip
    refused(
        capsys,
        ["run", "--axis", "rotary", "--reference", "constant:value=1600", "--out",
         str(tmp_path / "b")],
        "--reference", "±1500 rpm",
    )  # fmt: skip
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
    # a valve stuck open drives the piston to the soft limit: the supervisor trips -> exit 3
    out = tmp_path / "stuck"
    rc = main(["run", *SHORT[:-4], "--duration", "1.5", "--window-start", "0.1",
               "--fault", "valve_stuck:axis=linear,volts=10,start_s=0.2,duration_s=5",
               "--out", str(out)])  # fmt: skip
    assert rc == 3
    text = capsys.readouterr().out
    assert "safety  linear  SAFE at the end" in text and "stroke_limit" in text
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["safety_stopped"] is True


def test_unclear_cases_now_say_why(done, tmp_path, capsys):
    # a run shorter than the default window: says why and what to pass
    out = tmp_path / "short"
    assert main(["run", *SHORT[:-2], "--out", str(out)]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    assert "no steady-state window: it opens at 8.00 s, after the run's end at 0.30 s" in line
    assert "--window-start" in line and "nan" not in line
    # analyze --window-start nan
    refused(capsys, ["analyze", str(done / "run.mcap"), "--window-start", "nan"], "--window-start")
    # a fault that would start after the run, and one on the inactive axis
    refused(capsys, ["run", *SHORT, "--fault", "controller_silent:start_s=5", "--out",
                     str(tmp_path / "f")], "--fault controller_silent.start_s", "inside the run")  # fmt: skip
    refused(capsys, ["run", *SHORT, "--fault", "encoder_missed:start_s=0.1", "--out", str(tmp_path / "f")],
            "--fault", "active axis", "rotary")  # fmt: skip
    refused(capsys, ["run", *SHORT, "--reference", "sine:amplitude=1,amplitude=2", "--out",
                     str(tmp_path / "f")], "--reference", "each key once")  # fmt: skip
    assert not (tmp_path / "f").exists()


def test_a_foreign_bag_is_named_as_such(tmp_path, capsys):
    from mcap_ros2.writer import Writer

    bag = tmp_path / "chatter.mcap"
    with open(bag, "wb") as f:
        w = Writer(f)
        schema = w.register_msgdef("std_msgs/msg/String", "string data")
        for i in range(3):
            w.write_message("/chatter", schema, {"data": f"hi {i}"}, log_time=i, publish_time=i)
        w.finish()
    for cmd in (["analyze"], ["plot"], ["compare"], ["replay"]):
        argv = [*cmd, str(bag)] + (["--out", str(tmp_path / "x.mcap")] if cmd == ["replay"] else [])
        refused(capsys, argv, str(bag), "not a pneu run: no /pneu topics; found /chatter "
                "(std_msgs/msg/String)")  # fmt: skip


def test_the_newer_commands_claim_their_outputs_the_same_way(done, tmp_path, capsys):
    """sweep, excite, rig, validate, identify: a non-empty output refused unless --overwrite,
    an output that is an input refused always, the files there untouched."""
    bag = str(done / "run.mcap")
    d = tmp_path / "d"
    d.mkdir()
    (d / "keep.txt").write_text("mine\n")
    sweep = ["sweep", "--samples", "1", "--reference", "sine:amplitude=10,frequency_hz=1",
             "--duration", "0.05", "--controller", "pid", "--gains", "retuned",
             "--executor", "serial", "--no-plots"]  # fmt: skip
    rig = ["rig", "--backend", "sim:seed=1", "--axis", "linear", "--duration", "0.05"]
    for argv in (sweep, ["excite", "--level", "quick"], rig, ["validate", bag]):
        refused(capsys, [*argv, "--out", str(d)], "--out", "--overwrite", "keep.txt")
    # with --overwrite: their own files replaced, others left alone (quick ones only)
    for argv, names in ((sweep, ["summary.json", "summary.md", "sweep.csv", "envelopes.npz"]),
                        (rig, ["loop.json", "run.mcap"]), (["validate", bag], ["validate.json"])):  # fmt: skip
        assert main([*argv, "--out", str(d), "--overwrite"]) == 0
        assert (d / "keep.txt").read_text() == "mine\n"
        assert all((d / n).is_file() for n in names), sorted(p.name for p in d.iterdir())
        assert not list(d.glob("*.partial")) and not (d / ".pneu.lock").exists()
    # an output that is an input: never
    plant = tmp_path / "p.yaml"
    plant.write_text("keep\n")
    refused(capsys, ["identify", bag, "--out", str(plant)], "--out", "--overwrite")
    refused(capsys, ["identify", bag, "--base", str(plant), "--out", str(plant), "--force"],
            "--out", "inputs")  # fmt: skip
    refused(capsys, ["identify", bag, "--out", str(tmp_path / "p.txt")], "--out", ".yaml")
    assert plant.read_text() == "keep\n" and not (tmp_path / "p.txt").exists()
