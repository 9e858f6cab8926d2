"""The second round of hostile inputs (issue 22, part 4), each at its cause.

Every refusal is one line ``pneu CMD: error: FIELD: ...`` naming the field and the true
allowed range, exit 2, and nothing written; inputs are never lost to ``--overwrite``;
interrupted outputs say so. The property test (test_property.py) throws generated
inputs at the same rules; these are the cases that were found, as a user would type them.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import json
import os
import re
import signal
import socket
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
from pneu_control.cli.main import main
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.paths import config_file
from pneu_msgs_py.params.spec import parse_spec, parse_value

_spec = importlib.util.spec_from_file_location("_proc", Path(__file__).with_name("_proc.py"))
P = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(P)

RUN = ["run", "--axis", "linear", "--controller", "pid", "--duration", "0.05"]
MAX_LINE = 300  # an error line of reasonable length, whatever was refused (paths aside)


def pneu(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with (
        contextlib.redirect_stdout(out),
        contextlib.redirect_stderr(err),
        warnings.catch_warnings(),
    ):
        warnings.simplefilter("ignore")
        rc = main([str(a) for a in argv])
    return rc, out.getvalue(), err.getvalue()


def refused(*argv: str, field: str, allowed: str = "") -> str:
    """``pneu ARGV`` exits 2 with one short line naming ``field`` (and ``allowed``)."""
    rc, _, err = pneu(*argv)
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("pneu: warning:")]
    assert rc == 2, (argv, rc, err)
    assert len(lines) == 1 and lines[0].startswith(f"pneu {argv[0]}: error: "), (argv, err)
    assert field in lines[0] and allowed in lines[0], (argv, lines[0])
    assert len(re.sub(r"/[^\s',;)]+", "PATH", lines[0])) <= MAX_LINE, (argv, lines[0])
    return lines[0]


# ------------------------------------------------------------- values as typed
def test_values_are_read_as_typed_not_as_yaml_1_1():
    assert parse_value("010") == 10 and parse_value("0o10") == 8 and parse_value("0x10") == 16
    assert parse_value("3e5") == 3e5 and parse_value("-1.5") == -1.5
    for text in ("1:00", "1_000", "yes", "on", "2024-01-01"):  # YAML 1.1: 60, 1000, true, date
        assert isinstance(parse_value(text), str), text


def test_sexagesimal_refused_and_a_leading_zero_read_decimal(tmp_path):
    refused(*RUN, "--out", tmp_path / "a", "--reference", "constant:value=1:00",
            field="reference.value", allowed="a number")  # fmt: skip
    assert not (tmp_path / "a").exists()
    rc, _, err = pneu(*RUN, "--out", tmp_path / "b", "--reference", "constant:value=010")
    assert rc in (0, 3), err
    doc = json.loads((tmp_path / "b" / "metrics.json").read_text())
    assert doc["config"]["controllers"]["linear"]["reference"]["value"] == 10.0  # not 8


def test_a_config_file_reads_values_as_typed(tmp_path):
    text = config_file("plant.yaml").read_text()
    bad = tmp_path / "plant.yaml"
    bad.write_text(text.replace("M: {value: ", "M: {value: 1:00, was: ", 1))
    line = refused(*RUN, "--out", tmp_path / "o", "--plant", bad, field="--plant")
    assert str(bad) in line


def test_a_kind_key_inside_a_spec_is_refused(tmp_path):
    with pytest.raises(ParamError, match="no key 'kind': the kind is written before ':'"):
        parse_spec("sine:kind=constant", "--reference")
    refused(*RUN, "--out", tmp_path / "o", "--reference", "sine:kind=constant",
            field="--reference sine", allowed="no key 'kind'")  # fmt: skip
    refused(*RUN, "--out", tmp_path / "o", "--fault", "noise_burst:kind=valve_stuck",
            field="--fault noise_burst")  # fmt: skip
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------------------ true ranges
@pytest.mark.parametrize(
    "reference, field, allowed",
    [
        ("sine:amplitude=5,frequency_hz=1e-300", "frequency_hz", "[1/600, "),
        ("sine:amplitude=5,t0_s=1e300", "t0_s", "[0, 600] s"),
        ("smooth_step:target=5,duration_s=1e300", "duration_s", "[0, 600] s"),
        ("ramp:slope=1,duration_s=1e300", "duration_s", "[0, 600] s"),
    ],
)
def test_absurd_frequencies_and_times_are_refused(tmp_path, reference, field, allowed):
    refused(*RUN, "--out", tmp_path / "o", "--reference", reference, field=field, allowed=allowed)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "rows, allowed",
    [("0,0\n1e-300,5\n1,5\n", "at least one sample period"), ("0,0\n1e300,5\n", "[0, 600] s")],
)
def test_waypoints_inside_the_cap_and_a_sample_apart(tmp_path, rows, allowed):
    (tmp_path / "w.csv").write_text(rows)
    refused(*RUN, "--out", tmp_path / "o", "--reference", f"waypoints:file={tmp_path / 'w.csv'}",
            field="reference.file[1].t", allowed=allowed)  # fmt: skip


def test_validate_min_fit_and_horizon_ranges(tmp_path):
    bag = tmp_path / "none.mcap"  # the options are checked before any bag is read
    refused("validate", bag, "--min-fit", "200", field="--min-fit", allowed="<= 100")
    refused("validate", bag, "--horizon", "1e-300", field="--horizon", allowed="[0.01, 600] s")


def test_paper_uncertainty_capped_like_a_sweep(tmp_path):
    refused("paper", "--out", tmp_path / "o", "--uncertainty", "10001", "--only",
            "smooth_step_eq38", field="--uncertainty", allowed="[0, 10000]")  # fmt: skip
    assert not (tmp_path / "o").exists()


# -------------------------------------------------------------- empty and alone
@pytest.mark.parametrize(
    "argv",
    [
        ["excite", "--axis", "linear", "--level", "quick", "--out", ""],
        [*RUN, "--out", " "],
        [*RUN, "--out", "o", "--plant", ""],
        [*RUN, "--out", "o", "--reference", ""],
        ["identify", "", "--out", "p.yaml"],
    ],
)
def test_an_empty_value_is_refused_never_read_as_the_current_directory(tmp_path, argv):
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        refused(*argv, field="argument", allowed="a value that is not empty")
    finally:
        os.chdir(cwd)
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("option, value", [("--live-wait", "5"), ("--live-pace", "fast"),
                                           ("--live-host", "0.0.0.0")])  # fmt: skip
def test_live_view_options_only_with_live(tmp_path, option, value):
    refused(*RUN, "--out", tmp_path / "o", option, value, field=option, allowed="only with --live")
    assert not (tmp_path / "o").exists()


def test_a_live_view_that_cannot_start_names_its_option(tmp_path):
    pytest.importorskip("foxglove")
    refused(*RUN, "--out", tmp_path / "o", "--live", "0", "--live-host", "nohost.invalid",
            field="--live-host: 'nohost.invalid'", allowed="a name or address of this machine")  # fmt: skip
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        refused("sim", "--duration", "0.05", "--no-plot", "--out", tmp_path / "o", "--live",
                str(port), field=f"--live: {port}", allowed="--live 0 picks a free port")  # fmt: skip
    assert not (tmp_path / "o").exists()


def test_an_error_about_a_wrong_file_is_one_short_line(tmp_path):
    line = refused("sim", "--duration", "0.05", "--out", tmp_path / "o", "--no-plot",
                   "--plant", config_file("controllers.yaml"), field="--plant")  # fmt: skip
    assert "linear_controller" in line and "ros__parameters': {" not in line


# ------------------------------------------------------------- nothing is lost
def test_an_input_inside_the_output_is_never_deleted_by_overwrite(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    wp = out / "metrics.json"
    wp.write_text("[[0, 0], [1, 5]]\n")  # waypoints as JSON: a .json file is read as such
    refused(*RUN, "--out", out, "--overwrite", "--reference", f"waypoints:file={wp}",
            field="--out", allowed="not inputs of the command")  # fmt: skip
    assert wp.read_text() == "[[0, 0], [1, 5]]\n" and sorted(p.name for p in out.iterdir()) == [
        "metrics.json"
    ]
    task = out / "task_report.md"  # a task file named like one of pneu task's reports
    task.write_text("segments:\n  - dwell: {duration_s: 0.05}\n")
    refused("task", task, "--out", out, "--overwrite", field="--out", allowed="not inputs")
    assert task.exists()


def test_an_output_that_is_a_device_or_pipe_is_never_replaced(tmp_path):
    fifo = tmp_path / "fifo.mcap"
    os.mkfifo(fifo)
    refused("recover", tmp_path / "in.mcap", "--out", fifo, "--overwrite", field="--out",
            allowed="a path for a regular file")  # fmt: skip
    assert fifo.is_fifo()
    refused("analyze", fifo, field=str(fifo), allowed="")  # an input pipe: never waited on
    refused(*RUN, "--out", tmp_path / "o", "--plant", fifo, field="not a regular file")


def test_identify_refuses_the_same_bag_twice_and_an_unwritable_output_before_the_fit(tmp_path):
    bag = tmp_path / "exb"
    bag.mkdir()
    (bag / "run.mcap").write_bytes(b"")  # checked before any bag is read
    refused("identify", bag, bag / "run.mcap", "--out", tmp_path / "p.yaml", field="BAG",
            allowed="each bag once")  # fmt: skip
    (tmp_path / "f").write_text("")
    refused("identify", bag, "--out", tmp_path / "f" / "p.yaml", field="--out",
            allowed="a location under a directory")  # fmt: skip
    if os.geteuid() != 0:  # root writes anywhere: a mode bit refuses nothing
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o555)
        refused("identify", bag, "--out", ro / "p.yaml", field="--out", allowed="writable")


def test_full_and_read_only_locations_are_refused_first(tmp_path, monkeypatch):
    real = os.statvfs

    class Fs:
        def __init__(self, path, **kw):
            st = real(path)
            for k in ("f_bsize", "f_blocks", "f_files"):
                setattr(self, k, getattr(st, k))
            self.f_frsize, self.f_bavail = st.f_frsize, kw.get("bavail", st.f_bavail)
            self.f_flag = kw.get("flag", st.f_flag)

    monkeypatch.setattr(os, "statvfs", lambda p: Fs(p, bavail=0))
    refused(*RUN, "--out", tmp_path / "o", field="--out", allowed="a location with free space")
    monkeypatch.setattr(os, "statvfs", lambda p: Fs(p, flag=os.ST_RDONLY))
    refused(*RUN, "--out", tmp_path / "o", field="--out", allowed="read-only file system")
    assert not (tmp_path / "o").exists()


def test_a_tree_read_by_the_strict_reader_dumps_back():
    """identify on a one-axis bag keeps the other axis's leaves as read (MarkedDicts, with
    their alternatives): they write back (the RepresenterError after a whole fit)."""
    from pneu_msgs_py.params.yaml_file import load_yaml
    from pneu_sim.physics.plant_file import params_from_tree, plant_tree_yaml

    tree = load_yaml(config_file("plant.yaml"))
    text = plant_tree_yaml(tree, ["# test"])
    assert "alternatives: {gauge: " in text
    import yaml

    params_from_tree(yaml.safe_load(text))


def test_validate_refuses_a_bag_with_nothing_to_compare(tmp_path):
    """Open loop from the first sample needs valid samples from the first: a run whose
    supervisor acted at once has none; refused naming the bag, nothing written."""
    run = tmp_path / "run"
    rc, _, err = pneu("run", "--axis", "linear", "--controller", "pid", "--duration", "0.3",
                      "--fault", "controller_nan:start_s=0.02,duration_s=0.1", "--out", run)  # fmt: skip
    assert rc in (0, 3), err
    line = refused("validate", run, "--out", tmp_path / "v", field="BAG",
                   allowed="a bag with a stretch to compare")  # fmt: skip
    assert "--horizon" in line and not (tmp_path / "v").exists()


def test_validate_on_a_run_bag_says_why_for_each_axis(tmp_path):
    """The issue's ``pneu validate BAG_DIR/lin``: a run whose supervisor warned at 0.49 s has
    valid stretches of 0.2 s only; the refusal named just the rotary axis (not in the bag)
    and not why the linear one had nothing at the judged horizon."""
    run = tmp_path / "lin"
    rc, _, err = pneu("run", "--duration", "2", "--out", run)  # pneu run's defaults
    assert rc in (0, 3), err
    line = refused("validate", run, "--out", tmp_path / "v", field="BAG",
                   allowed="linear: no valid stretch of 1 s (supervisor event at sample")  # fmt: skip
    assert "it has 0.2 s" in line and "try --horizon" in line and "rotary: not in this bag" in line
    assert not (tmp_path / "v").exists()
    rc, out, err = pneu("validate", run, "--horizon", "0.2")  # as the line suggests
    assert rc == 0 and "0.2 s (judged)" in out, err


def test_validate_refuses_overwrite_without_out_and_a_foreign_report(tmp_path, short_bag):
    refused("validate", short_bag, "--overwrite", field="--overwrite", allowed="only with --out")
    plant = tmp_path / "plant.yaml"
    plant.write_text(config_file("plant.yaml").read_text())
    for text in ('{"bags": 5}', "[1]", "{nope"):  # Python's own words before ('int' object ...)
        (tmp_path / "plant.identify.json").write_text(text)
        line = refused("validate", short_bag, "--plant", plant, field="--plant",
                       allowed="a report of pneu identify beside the plant file (")  # fmt: skip
        assert "is not iterable" not in line and "has no attribute" not in line, line


# ------------------------------------------------------------------------ Dask
def _dead_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]  # closed on exit: nothing listens there


SWEEP = ["sweep", "--samples", "1", "--reference", "sine:amplitude=10,frequency_hz=1",
         "--duration", "0.05", "--controller", "pid", "--gains", "retuned",
         "--executor", "dask"]  # fmt: skip


@pytest.mark.parametrize(
    "address, allowed",
    [
        ("garbage", "tcp://HOST:PORT"),
        ("tcp://127.0.0.1:99999", "PORT in [1, 65535]"),
        ("http://127.0.0.1:8786", "tcp://HOST:PORT"),
        (None, "a running Dask scheduler"),
    ],
)
def test_a_dask_address_is_checked_before_anything_is_written(tmp_path, address, allowed):
    address = address or f"tcp://127.0.0.1:{_dead_port()}"
    refused(*SWEEP, "--out", tmp_path / "o", "--address", address, field="--address",
            allowed=allowed)  # fmt: skip
    assert not (tmp_path / "o").exists()


# -------------------------------------------------------------- interruptions
def _wait_for_text(path: Path, text: str, proc: subprocess.Popen) -> None:
    assert P.wait_for(
        lambda: (
            proc.poll() is not None or (path.exists() and text in path.read_text(errors="replace"))
        )
    ), path
    assert proc.poll() is None, path.read_text()


def test_sim_interrupted_says_so_in_its_csv(tmp_path):
    err = tmp_path / "err.txt"
    with open(err, "w") as fh:
        proc = subprocess.Popen([*P.PNEU, "sim", "--duration", "600", "--out", tmp_path / "o",
                                 "--no-plot"], stdout=subprocess.DEVNULL, stderr=fh,
                                env=dict(os.environ, PYTHONUNBUFFERED="1"))  # fmt: skip
        _wait_for_text(err, "steps", proc)  # the loop runs: its first progress line
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=300) == 130, err.read_text()
    lines = (tmp_path / "o" / "sim.csv").read_text().splitlines()
    assert lines[-1].startswith("# interrupted by SIGINT at ") and " of 600 s" in lines[-1]
    assert len(lines) > 3 and not lines[-2].startswith("#")


def test_paper_interrupted_in_its_uncertainty_stage_says_so(tmp_path):
    out, err = tmp_path / "o", tmp_path / "err.txt"
    with open(err, "w") as fh:
        proc = subprocess.Popen([*P.PNEU, "paper", "--out", out, "--uncertainty", "50",
                                 "--only", "smooth_step_eq38", "--no-plots", "--seeds", "1",
                                 "--executor", "serial"], stdout=subprocess.DEVNULL, stderr=fh,
                                env=dict(os.environ, PYTHONUNBUFFERED="1"))  # fmt: skip
        # the nominal table is written (as one, under deferred signals) before the band stage
        assert P.wait_for(lambda: (out / "paper_table.md").exists() or proc.poll() is not None)
        assert proc.poll() is None, err.read_text()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=300) == 143, err.read_text()
    doc = json.loads((out / "paper_table.json").read_text())
    assert doc["uncertainty"]["status"] == "interrupted"
    assert doc["uncertainty"]["signal"] == "SIGTERM" and doc["experiments"]
    assert "## Over 50 plant samples: interrupted" in (out / "paper_table.md").read_text()
    assert not (out / "uncertainty").exists()


@pytest.fixture(scope="module")
def excitation(tmp_path_factory) -> Path:
    """A linear-only quick excitation (pneu excite's bag directory)."""
    out = tmp_path_factory.mktemp("exl") / "exl"
    rc, _, err = pneu("excite", "--axis", "linear", "--level", "quick", "--out", out)
    assert rc == 0, err
    return out


@pytest.mark.parametrize("axis", ["rotary", "both"])
def test_identify_refuses_an_axis_the_bags_do_not_excite_in_one_line(tmp_path, excitation, axis):
    """``--axis rotary`` on a linear excitation: 'read ...' and 'rotary: fitting 11 parameters
    to 0 bag(s)' were printed before the error (or, with both, the linear fit ran first)."""
    refused("identify", excitation, "--axis", axis, "--out", tmp_path / "p.yaml",
            field="--axis", allowed="an axis the bags excite (linear)")  # fmt: skip
    assert list(tmp_path.iterdir()) == []


def test_identify_refuses_bags_that_excite_nothing(tmp_path):
    held = tmp_path / "held.mcap"  # the rig holding the valve at 5 V: nothing excited
    rc, _, err = pneu("rig", "--backend", "sim", "--duration", "0.3", "--hold", "linear=5",
                      "--out", tmp_path / "r")  # fmt: skip
    assert rc in (0, 3), err
    (tmp_path / "r" / "run.mcap").rename(held)
    refused("identify", held, "--out", tmp_path / "p.yaml", field="BAG",
            allowed="bags that excite an axis")  # fmt: skip
    assert not (tmp_path / "p.yaml").exists()


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "--axis", "linear", "--controller", "pid", "--duration", "20"],
        ["validate", "{exl}"],  # its first figure was left as validate_00_..._linear.png.partial
        ["task", str(config_file("tasks/screw_in.yaml"))],
    ],
)
def test_a_full_disk_mid_run_is_one_line_and_leaves_no_partial(tmp_path, argv, request):
    """A write that fails (here a file-size limit, as a full disk fails it) ends the command
    with one line saying so, exit 1, and no half-written file."""
    import resource

    def limit() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails (EFBIG), no kill
        resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, 100_000))

    if "{exl}" in argv:
        argv = [str(request.getfixturevalue("excitation")) if a == "{exl}" else a for a in argv]
    out = tmp_path / "o"
    proc = subprocess.run([*P.PNEU, *argv, "--out", out], capture_output=True, text=True,
                          preexec_fn=limit, timeout=600)  # fmt: skip
    lines = [ln for ln in proc.stderr.splitlines() if "error" in ln]
    assert proc.returncode == 1 and len(lines) == 1, proc.stderr
    assert "a full disk or a file-size limit" in lines[0], lines
    assert "Traceback" not in proc.stderr and "internal error" not in proc.stderr
    assert not out.exists() or not [p for p in out.iterdir() if p.name.endswith(".partial")]


@pytest.mark.parametrize(
    "argv, name",
    [
        ([*RUN, "--out"], "{long}"),  # rc 1 'File name too long' before: a stat, not a check
        (["recover", "{bag}", "--out"], "{long}.mcap"),
        (["plot", "{bag}", "--out"], "{long}.png"),
        (["identify", "{bag}", "--out"], "{long}.yaml"),
    ],
)
def test_an_output_name_too_long_is_refused_first(tmp_path, short_bag, argv, name):
    argv = [str(short_bag) if a == "{bag}" else a for a in argv]
    out = tmp_path / name.replace("{long}", "n" * 300)
    refused(*argv, out, field="--out", allowed="names of at most 255 bytes")
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------- refused option combinations
@pytest.fixture(scope="module")
def short_bag(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bag") / "run"
    rc, _, err = pneu(*RUN[:-1], "0.3", "--out", out)
    assert rc in (0, 3), err
    return out / "run.mcap"


@pytest.mark.parametrize(
    "argv, field",
    [
        ([*RUN, "--duration", "600"], "--duration"),  # the last would silently win
        ([*RUN, "--dur", "600"], "--duration"),  # an abbreviation is the same option
        ([*RUN, "--overwrite", "--overwrite"], "--overwrite"),
        (["identify", "b.mcap", "--out", "p.yaml", "--out", "q.yaml"], "--out"),
    ],
)
def test_an_option_given_twice_is_refused(tmp_path, argv, field):
    line = refused(*argv, "--out", tmp_path / "o", field=f"argument {field}",
                   allowed="each option once")  # fmt: skip
    assert "given twice" in line and not (tmp_path / "o").exists()


def test_repeatable_options_still_repeat(tmp_path):
    rc, _, err = pneu(*RUN, "--out", tmp_path / "o", "--set", "pid.kp=1",
                      "--set", "pid.ki=0", "--fault", "noise_burst:start_s=0.01,duration_s=0.01",
                      "--fault", "noise_burst:start_s=0.03,duration_s=0.01")  # fmt: skip
    assert rc in (0, 3), err
    doc = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert doc["config"]["controllers"]["linear"]["pid"]["kp"] == 1.0
    assert len(doc["config"]["faults"]) == 2


@pytest.mark.parametrize(
    "extra, field, allowed",
    [
        (["--set", "pid.kp=1", "--set", "linear.pid.kp=2"], "--set linear.pid.kp",
         "each key once per axis (already --set pid.kp=1"),
        (["--set", "algorithm=ladrc"], "--set algorithm", "--controller sets algorithm"),
        (["--reference", "constant:value=3", "--set", "reference.value=4"],
         "--set reference.value", "--reference sets reference.value"),
        (["--safety", "none.yaml", "--no-safety"], "--safety", "not with --no-safety"),
    ],
)  # fmt: skip
def test_a_value_set_twice_is_refused(tmp_path, extra, field, allowed):
    refused(*RUN, "--out", tmp_path / "o", *extra, field=field, allowed=allowed)
    assert not (tmp_path / "o").exists()


def test_replay_refuses_an_algorithm_set_twice(tmp_path, short_bag):
    refused("replay", short_bag, "--out", tmp_path / "r.mcap", "--controller", "pid",
            "--set", "algorithm=ladrc", field="--set algorithm",
            allowed="--controller sets algorithm")  # fmt: skip
    assert not (tmp_path / "r.mcap").exists()


@pytest.mark.parametrize(
    "extra, field, allowed",
    [
        (["--duration", "5"], "--duration", "only with --reference"),
        (["--axis", "rotary"], "--axis", "only with --reference"),
        (["--window-start", "1"], "--window-start", "only with --reference"),
        (["--executor", "serial", "--workers", "2"], "--workers",
         "(serial runs in this process)"),
        (["--executor", "dask", "--address", "tcp://127.0.0.1:1", "--workers", "2"],
         "--workers", "the cluster at --address has its own"),  # refused before any probe
    ],
)  # fmt: skip
def test_sweep_options_that_would_be_ignored_are_refused(tmp_path, extra, field, allowed):
    refused("sweep", "--out", tmp_path / "o", "--samples", "1", "--experiment",
            "smooth_step_eq38", *extra, field=field, allowed=allowed)  # fmt: skip
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "extra", [["--executor", "serial"], ["--workers", "2"], ["--sampler", "sobol"]]
)
def test_paper_executor_options_only_with_a_band_stage(tmp_path, extra):
    refused("paper", "--out", tmp_path / "o", "--only", "smooth_step_eq38", *extra,
            field=extra[0], allowed="only with --uncertainty N")  # fmt: skip
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "extra, field",
    [
        (["--hold", "linear=5", "--controller", "pid"], "--controller"),
        (["--hold", "linear=5", "--reference", "constant:value=3"], "--reference"),
        (["--axis", "both", "--hold", "linear=5,rotary=5", "--set", "pid.kp=1"], "--set"),
    ],
)
def test_rig_refuses_controller_options_when_every_axis_is_held(tmp_path, extra, field):
    refused("rig", "--backend", "sim", "--duration", "0.05", "--out", tmp_path / "o", *extra,
            field=field, allowed="only for an axis a controller runs on")  # fmt: skip
    assert not (tmp_path / "o").exists()


def test_a_window_start_after_the_run_is_refused(short_bag):
    refused("analyze", short_bag, "--window-start", "1e9", field="--window-start",
            allowed="inside the run (its last sample is at 0.299 s)")  # fmt: skip
    rc, out, err = pneu("analyze", short_bag, "--window-start", "0.2")
    assert rc == 0 and "window 0.20–0.30 s" in out, err


# ----------------------------------------------------------- numbers as typed
@pytest.mark.parametrize(
    "argv, field",
    [
        (["sim", "--duration", "0.05", "--no-plot", "--linear-voltage", "0_5"],
         "--linear-voltage"),  # Python's float would read 5 V
        ([*RUN, "--live", "8_765"], "--live"),
        ([*RUN, "--live", "0", "--live-wait", "0_1"], "--live-wait"),  # 1 s, not 0.1 s
    ],
)  # fmt: skip
def test_numbers_of_every_option_read_as_typed(tmp_path, argv, field):
    refused(*argv, "--out", tmp_path / "o", field=f"argument {field}", allowed="not a number"
            if field != "--live" else "not an integer")  # fmt: skip
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------- recover, read-only
def test_a_cut_bag_recovers_onto_its_own_final_name(tmp_path, short_bag):
    """``pneu recover run.mcap.partial --out run.mcap`` (what a kill leaves, onto the name it
    was to have): written as run.mcap.new.partial, the source kept byte for byte."""
    from mcap_ros2.reader import read_ros2_messages

    d = tmp_path / "killed"
    d.mkdir()
    cut = d / "run.mcap.partial"
    data = short_bag.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    rc, out, err = pneu("recover", cut, "--out", d / "run.mcap")
    assert rc == 0, err
    assert "recovered" in out and f"kept {cut}" in out
    assert cut.read_bytes() == data[: len(data) * 2 // 3]
    assert sorted(p.name for p in d.iterdir()) == ["run.mcap", "run.mcap.partial"]
    n = sum(1 for _ in read_ros2_messages(str(d / "run.mcap")))  # complete, indexed
    assert n > 0
    refused("recover", cut, "--out", d / "run.mcap", field="--out", allowed="--overwrite")
    rc, _, err = pneu("recover", cut, "--out", d / "run.mcap", "--overwrite")
    assert rc == 0 and cut.exists(), err


def test_a_partial_left_by_a_killed_command_is_named_first(tmp_path, short_bag):
    stale = tmp_path / "r.mcap.partial"
    stale.write_bytes(b"half a bag")
    line = refused("recover", short_bag, "--out", tmp_path / "r.mcap", field="--out",
                   allowed="r.mcap.partial is left by a command that did not finish")  # fmt: skip
    assert "pneu recover it" in line and stale.read_bytes() == b"half a bag"
    rc, _, err = pneu("recover", short_bag, "--out", tmp_path / "r.mcap", "--overwrite")
    assert rc == 0 and not stale.exists() and (tmp_path / "r.mcap").exists(), err


def test_a_read_only_file_system_is_named_as_such(tmp_path, monkeypatch):
    """On a read-only file system access(W_OK) fails too (EROFS, even for root): the line
    says read-only, not 'permission denied'."""
    real = os.statvfs

    class Ro:
        def __init__(self, path):
            st = real(path)
            self.f_frsize, self.f_bavail, self.f_flag = st.f_frsize, st.f_bavail, os.ST_RDONLY

    monkeypatch.setattr(os, "statvfs", Ro)
    monkeypatch.setattr(os, "access", lambda *a, **k: False)
    line = refused(*RUN, "--out", tmp_path / "o", field="--out",
                   allowed="is on a read-only file system")  # fmt: skip
    assert "permission denied" not in line


def test_a_real_read_only_mount_is_named_as_such(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "none", str(ro)],
                      capture_output=True).returncode != 0:  # fmt: skip
        pytest.skip("cannot mount a read-only tmpfs here (not root)")
    try:
        for argv in ([*RUN, "--out", ro / "o"], ["tune", "--out", ro / "t.yaml"]):
            refused(*argv, field="--out", allowed="is on a read-only file system")
    finally:
        subprocess.run(["umount", str(ro)], check=True)


def test_numbas_note_on_record_subtypes_is_not_shown():
    """Compiling the fast loop (a fresh clone, an empty numba cache) passes each
    algorithm's state record where the base record is taken: by design; numba's ~2 kB
    note on it is not a warning line for the user."""
    from numba.core.errors import NumbaExperimentalFeatureWarning
    from pneu_control.fastloop import loop  # importing it installs the filter

    with warnings.catch_warnings(record=True) as seen:
        loop.quiet_record_subtypes()  # what the import did (pytest resets filters per test)
        warnings.warn_explicit(
            "Record(z1[type=float64;offset=0],k[type=int64;offset=8];16;False) has been "
            "considered a subtype of Record(z1[type=float64;offset=0];8;False)  This is an "
            "experimental feature.",
            NumbaExperimentalFeatureWarning, loop.__file__, 130,
        )  # fmt: skip
        warnings.warn_explicit("another note", NumbaExperimentalFeatureWarning, loop.__file__, 1)
    assert [str(w.message) for w in seen] == ["another note"]


@pytest.mark.parametrize("value", ["-inf", "-1e3", "-.5e2"])
def test_a_negative_number_is_a_value_not_an_option(tmp_path, value):
    """argparse takes only -5 and -.5 for numbers: '--window-start -1e3' was "expected one
    argument"; now the option's own range refuses it."""
    refused(*RUN, "--out", tmp_path / "o", "--window-start", value, field="--window-start",
            allowed="inside the run")  # fmt: skip


# ---------------------------------------------------------------- config files
@pytest.mark.parametrize(
    "text, allowed",
    [
        ("watchdog_ms: 100\x00\n", ":1:17: control character 0x00; allowed: text"),
        # nine aliases of nine aliases ...: 4e8 values from a few hundred bytes, at a key that
        # exists (shown or walked, it never ended)
        ("watchdog_ms: [" + "".join(f"&{c} [" for c in "abcdefghi") + "x" + "".join(
            "]" + f", *{c}" * 8 for c in "abcdefghi"[::-1]) + "]\n",
         "its aliases (*name) expand"),
    ],
)  # fmt: skip
def test_a_config_file_with_control_characters_or_a_yaml_bomb_is_one_line(tmp_path, text, allowed):
    bad = tmp_path / "safety.yaml"
    bad.write_text(text)
    refused(*RUN, "--out", tmp_path / "o", "--safety", bad, field="--safety", allowed=allowed)


@pytest.mark.parametrize(
    "reference, field, allowed",
    [
        ("constant:value=5,amplitude=3", "--reference constant", "a key of a constant reference"),
        ("constant:value=5,t0_s=1", "--reference constant", "known: value"),
        ("sine:amplitud=5", "--reference sine", "did you mean amplitude?"),
        ("x:y=1", "--reference", "a kind: one of sine"),  # the kind, not its key
    ],
)
def test_a_reference_key_its_kind_does_not_read_is_refused(tmp_path, reference, field, allowed):
    refused(*RUN, "--out", tmp_path / "o", "--reference", reference, field=field, allowed=allowed)


def test_a_set_reference_key_its_kind_does_not_read_is_refused(tmp_path):
    refused(*RUN, "--out", tmp_path / "o", "--set", "reference.kind=constant", "--set",
            "reference.amplitude=3", field="--set reference (constant)",
            allowed="a key of a constant reference")  # fmt: skip


# ----------------------------------------------------------------- waypoints
def _reference_of(out: Path) -> list[float]:
    import numpy as np

    return list(np.load(out / "timeseries.npz")["linear.reference"][:2] * 1e3)


def test_a_waypoint_file_with_a_bom_keeps_its_first_row(tmp_path):
    wp = tmp_path / "w.csv"
    wp.write_bytes(b"\xef\xbb\xbf" + b"0,0\n1,5\n2,5\n")  # Excel's UTF-8: a BOM first
    rc, _, err = pneu(*RUN, "--out", tmp_path / "o", "--reference", f"waypoints:file={wp}")
    assert rc in (0, 3), err
    assert _reference_of(tmp_path / "o")[0] == pytest.approx(0.0, abs=1e-6)  # not 5: row kept


@pytest.mark.parametrize(
    "name, text, field, allowed",
    [
        ("three.csv", "0,0,7\n1,5,9\n", "reference.file[row 1]", "two columns t, value"),
        ("extra.yaml", "t: [0, 1]\nvalue: [0, 5]\nextra: 1\n", "reference.file",
         "(it has keys extra, t, value)"),
        ("t.yaml", "t: 5\nvalue: 3\n", "reference.file", "t and value lists"),
        ("v.yaml", "t: [0, 1]\nvalue: 5\n", "reference.file", "t and value lists"),
    ],
)  # fmt: skip
def test_waypoint_files_read_whole_or_refused(tmp_path, name, text, field, allowed):
    (tmp_path / name).write_text(text)
    refused(*RUN, "--out", tmp_path / "o", "--reference", f"waypoints:file={tmp_path / name}",
            field=field, allowed=allowed)  # fmt: skip


@pytest.mark.parametrize(
    "name, text", [("c.csv", "# made by hand\nt,value\n0,0\n1,5,\n"), ("w.json", "[[0,0],[1,5]]")]
)
def test_waypoint_headers_after_comments_and_json_are_read(tmp_path, name, text):
    (tmp_path / name).write_text(text)
    rc, _, err = pneu(*RUN, "--out", tmp_path / "o", "--reference",
                      f"waypoints:file={tmp_path / name}")  # fmt: skip
    assert rc in (0, 3), err


# ---------------------------------------------------------------------- tasks
TASK_HEAD = "plumbing: bidirectional\nsegments:\n"


@pytest.mark.parametrize(
    "segment, field, allowed",
    [
        ("  - move: {to_mm: 10, duration_s: 1e-300}", "segments[0].move.duration_s",
         "[0.001, 599.8] s: at least one control sample"),
        ("  - spin: {speed_rpm: 60, duration_s: 1e-300}", "segments[0].spin.duration_s",
         "at least one control sample"),
        ("  - dwell: {duration_s: 1e-300}", "segments[0].dwell.duration_s", "[0.001, 599.8] s"),
        ("  - move: {to_mm: 10, speed_mm_s: 1e9}", "segments[0].move.speed_mm_s",
         "[0.0333444, 20000] mm/s"),
        ("  - screw: {pitch_mm: 1, turns: 1e-300, rate_turns_s: 1}", "segments[0].screw.turns",
         "ramp_s <= |turns|/rate_turns_s"),
        ("  - dwell: {duration_s: 0.1}\n    load: {bogus: 1}", "segments[0].load.bogus",
         "known: T_c, T_bk"),
        ("  - dwell: {duration_s: 0.1}\n    load: {T_bk: 1e300}", "segments[0].load.T_bk",
         "[0, 10] N*m"),
        ("  - dwell: {duration_s: 0.1}\n    name: [1, 2]", "segments[0].name", "a string"),
    ],
)  # fmt: skip
def test_a_task_segment_is_checked_whole_before_anything_is_written(
    tmp_path, segment, field, allowed
):
    """Each of these was found only by the run (after run.mcap was begun: a bag left, the
    line naming no segment), or not at all (a 1 GHz move aborted by the supervisor)."""
    task = tmp_path / "task.yaml"
    task.write_text(TASK_HEAD + segment + "\n")
    refused("task", task, "--out", tmp_path / "o", field=field, allowed=allowed)
    assert not (tmp_path / "o").exists()


# the third round: a task no run could carry (internal errors, a 23 GB trajectory), ranges
# said whole, and fields that would be silently unused
@pytest.mark.parametrize(
    "segment, field, allowed",
    [
        # 2·10 mm / 1e-300 mm/s: a 2e301 s motion (OverflowError: an internal error before)
        ("  - move: {to_mm: 10, speed_mm_s: 1e-300}", "segments[0].move.speed_mm_s",
         "[0.0333444, 20000] mm/s: the motion over at least one control sample (1 ms) and "
         "at most 599.8 s"),
        ("  - spin: {speed_rpm: 60, duration_s: 1e300}", "segments[0].spin.duration_s",
         "[0.001, 599.8] s"),  # OverflowError before
        # a 5e7 s helix: its trajectory filled 23 GB before the sum of timeouts was checked
        ("  - screw: {pitch_mm: 1e-9, turns: 1e9, rate_turns_s: 20}", "segments[0].screw.turns",
         "at most 14988.7 turns either way (at 25 turns/s, max_speed_rpm, within 599.8 s"),
        ("  - screw: {pitch_mm: 1, turns: 20, rate_turns_s: 0.01}",
         "segments[0].screw.rate_turns_s", "[0.0333584, 25] turns/s"),
        ("  - rotate: {turns: 1e6, speed_rpm: 600}", "segments[0].rotate",
         "a motion of at most 2.6991e+06° (at 1500 rpm, the supervisor's top speed"),
        ("  - rotate: {turns: 10, speed_rpm: 1e-3}", "segments[0].rotate.speed_rpm",
         "[2.00067, 1500] rpm"),
        ("  - dwell: {duration_s: 0.1}\n    timeout_s: 0", "segments[0].timeout_s",
         "[0.1, 599.8] s (at least the motion it bounds"),
        ("  - dwell: {duration_s: 0.1}\n    timeout_s: -1", "segments[0].timeout_s", "[0.1, 599.8]"),
        ("  - dwell: {duration_s: 0.1}\n    timeout_s: .inf", "segments[0].timeout_s",
         "[0.1, 599.8]"),  # was refused with "(0, inf) s", which reads as if inf were in
        ("  - wait: {}\n    until: {force: {above_n: 10}}\n    timeout_s: 1e300",
         "segments[0].timeout_s", "(0, 599.8] s"),
        ("  - dwell: {duration_s: 0.001}\n" * 300, "segments",
         "at most 599.8 s in all (the duration cap of a run, 600 s, less the 0.2 s safe tail)"),
        ("  - move: {to_mm: 10, speed_mm_s: 40}\n    until: {settled: {tol_mm: 1e300}}",
         "segments[0].until.settled.tol_mm", "(0, 150) mm (narrower than the stroke)"),
        ("  - rotate: {by_deg: 90, speed_rpm: 60}\n    until: {settled: {tol_deg: 720}}",
         "segments[0].until.settled.tol_deg", "(0, 360) ° (narrower than a turn)"),
        ("  - wait: {duration_s: 1}\n    until: {force: {above_n: 10}}",
         "segments[0].wait.duration_s", "no fields here"),  # "one of " and nothing before
    ],
)  # fmt: skip
def test_a_task_no_run_could_carry_is_refused_first(tmp_path, segment, field, allowed):
    task = tmp_path / "task.yaml"
    task.write_text(TASK_HEAD + segment + "\n")
    refused("task", task, "--out", tmp_path / "o", field=field, allowed=allowed)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "head, field, allowed",
    [
        ("controllers: {linear: {reference.kind: sine}}\n", "controllers.linear.reference.kind",
         "other than reference.* (the task's segments are the references)"),  # unused before
        ("controllers: {third: {}}\n", "controllers.third: an empty mapping {}",
         "linear or rotary"),  # "a mapping (0 keys: )" before
    ],
)  # fmt: skip
def test_task_controllers_refuse_what_a_task_never_reads(tmp_path, head, field, allowed):
    task = tmp_path / "task.yaml"
    task.write_text(head + TASK_HEAD + "  - dwell: {duration_s: 0.1}\n")
    refused("task", task, "--out", tmp_path / "o", field=field, allowed=allowed)


# --------------------------------------------------------------- pneu bench angle
@pytest.mark.parametrize(
    "extra, field, allowed",
    [
        (["--only", "plant"], "--only: 'plant'", "not with 'pneu bench angle'"),  # was 'True'
        (["--seed", str(2**32 - 1)], "--seed: 4294967295",  # was '--seed + --samples'
         "[0, 4294967255] (with --samples 40"),
        (["--safety", "/dev/zero"], "--safety: /dev/zero", "not a regular file"),  # unnamed
        (["--samples", "0"], "--samples", "[1, 1000]"),
        (["--serial", "--workers", "2"], "--workers", "not with --serial"),
        (["--overwrite"], "--overwrite", "only with --out"),
    ],
)  # fmt: skip
def test_bench_angle_options_are_refused_naming_the_option(tmp_path, extra, field, allowed):
    refused("bench", "angle", *extra, field=field, allowed=allowed)
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------ pneu security
@pytest.mark.parametrize(
    "domain, argv, field, allowed",
    [
        ("\u0663", [], "ROS_DOMAIN_ID", "0-232 in digits 0-9"),  # an Arabic-Indic 3: Python's int
        (None, [], "ROS_DOMAIN_ID: '(unset)'", "0-232"),
        ("233", [], "ROS_DOMAIN_ID", "0-232"),
        ("5", ["--operator", "a" * 50], "--operator: 'aaaaaaaaaaaa... (50 characters)'",
         "at most 49 characters (the enclave's certificate name"),  # sros2 failed at the end
        ("5", ["--operator", "bad name"], "--operator", "letters, digits and _"),
        ("5", ["--operator", "bob", "--operator", "bob"], "--operator", "each name once"),
    ],
)  # fmt: skip
def test_security_refuses_domains_and_operators_first(tmp_path, monkeypatch, domain, argv,
                                                      field, allowed):  # fmt: skip
    if domain is None:
        monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    else:
        monkeypatch.setenv("ROS_DOMAIN_ID", domain)
    refused("security", tmp_path / "ks", *argv, field=field, allowed=allowed)
    assert not (tmp_path / "ks").exists()


def test_security_checks_the_keystore_location_first(tmp_path, monkeypatch):
    """Under a file or on a full or read-only location the keystore was found unwritable by
    sros2, after the checks (exit 1, a part of it made)."""
    monkeypatch.setenv("ROS_DOMAIN_ID", "5")
    (tmp_path / "f").write_text("")
    refused("security", tmp_path / "f" / "ks", field="KEYSTORE",
            allowed="a location under a directory")  # fmt: skip
    refused("security", tmp_path / "f", field="KEYSTORE", allowed="a directory")
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "keep.txt").write_text("mine")
    refused("security", tmp_path / "d", field="KEYSTORE", allowed="a keystore this command made")
    real = os.statvfs

    class Ro:
        def __init__(self, path):
            st = real(path)
            self.f_frsize, self.f_bavail, self.f_flag = st.f_frsize, st.f_bavail, os.ST_RDONLY

    monkeypatch.setattr(os, "statvfs", Ro)
    refused("security", tmp_path / "ks", field="KEYSTORE", allowed="read-only file system")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d", "f"]


# --------------------------------------------- found by the longer property run
def test_sweep_names_its_plant_file(tmp_path, short_bag):
    """A bag given as --plant: 'pneu sweep: error: PATH: not UTF-8 text' named no option."""
    refused("sweep", "--samples", "1", "--experiment", "smooth_step_eq38", "--plant",
            short_bag, "--out", tmp_path / "o", field="--plant", allowed="not UTF-8 text")  # fmt: skip
    assert not (tmp_path / "o").exists()


def test_a_refused_table_is_shown_by_its_size(tmp_path):
    """An unknown key holding a 17-value table (a copied valve_du_table): the line showed
    every value and ran to 359 characters."""
    text = config_file("controllers.yaml").read_text()
    table = "[" + ", ".join(f"{0.3 * i:.2f}" for i in range(17)) + "]"
    bad = tmp_path / "controllers.yaml"
    bad.write_text(text.replace("    pid:\n", f"    valve_du_table_x: {table}\n    pid:\n", 1))
    refused(*RUN, "--out", tmp_path / "o", "--controllers", bad, field="valve_du_table_x",
            allowed="no such parameter")  # fmt: skip
    assert "a list of 17 items" in pneu(*RUN, "--out", tmp_path / "o", "--controllers", bad)[2]


# ------------------------------------------------------------ the parser itself
@pytest.mark.parametrize(
    "argv, allowed",
    [
        (["recover", "a.mcap", "b.mcap"], "unrecognized arguments: b.mcap"),
        ([*RUN, "\u2014duration", "1"], "unrecognized arguments: \u2014duration 1; did you mean "
         "--duration?"),  # a dash a word processor made typographic
        ([*RUN, "--durations", "1"], "did you mean --duration?"),
    ],
)  # fmt: skip
def test_an_unknown_argument_is_refused_by_its_subcommand(tmp_path, argv, allowed):
    """argparse's own line was ``pneu: error: unrecognized arguments`` whatever the
    subcommand; now the subcommand's, with the option the token resembles."""
    line = refused(*argv, "--out", tmp_path / "o", field="unrecognized", allowed=allowed)
    assert line.endswith(f"(see pneu {argv[0]} --help)")
    assert not (tmp_path / "o").exists()


def test_an_unknown_no_option_is_not_offered_its_opposite(tmp_path):
    line = refused("excite", "--axis", "linear", "--no-safety", "--out", tmp_path / "o",
                   field="unrecognized arguments: --no-safety")  # fmt: skip
    assert "did you mean --safety" not in line  # the opposite of what was asked


def test_a_closed_stdout_pipe_keeps_the_exit_code(tmp_path):
    """``pneu run ... | head -0``: the reader gone, the run still finishes its files and exits
    with its own code (3: the supervisor acted), not 0 (a BrokenPipeError took the code)."""
    out = tmp_path / "o"
    proc = subprocess.Popen([*P.PNEU, *RUN[:-1], "0.3", "--fault",
                             "controller_nan:start_s=0.02,duration_s=0.1", "--out", out],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip
    proc.stdout.close()  # before anything was printed
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == 3, err
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert json.loads((out / "metrics.json").read_text())["safety_stopped"], err


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))
