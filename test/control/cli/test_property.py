"""Property: whatever arguments and config values a user throws at any ``pneu`` subcommand,

- no traceback, and no "internal error";
- an exit code from the documented set (0 success, 2 bad input, 3 safety stop);
- every refusal (exit 2) is one line ``pneu CMD: error: ...`` naming a field the
  example changed, and nothing was created at the output path.

Arguments are generated around a valid base command of each subcommand: numbers
(NaN, inf, huge, negative, not numbers, YAML 1.1 readings: ``1:00``, ``010``,
``1_000``), ``KIND:k=v`` specs with known and unknown keys (``kind`` too),
``--set`` pairs, paths (missing, a directory, a corrupt bag, a foreign bag, a
YAML file, a pipe, a device), empty values, the newer options (``--live-*``,
``--address``, ``--uncertainty``, ``--backend``, ``--hold``, ``--horizon``,
``--plumbing``) and config files with one key given a generated value, deleted
or given twice. Long commands (paper, tune, excite, identify, task, bench) only
get refusals: a valid example would run for minutes. Every refusal line is of
reasonable length (paths aside).

The environment is varied too (:func:`test_environment_oddities`, real
processes): stdout closed or a pipe closed by its reader, ``HOME`` unset,
``LANG=C``/``LC_ALL=C``, an output location that is read-only, a file, or full
(a file-size limit fails the writes as a full disk does), and paths with spaces
and non-ASCII characters: no traceback, a documented exit code, one error line,
finished outputs or none, never a ``.partial`` left.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import tempfile
import warnings
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from pneu_control.cli.main import main
from pneu_msgs_py.params.paths import config_file

DOCUMENTED = {0, 2, 3}  # 1 would be a runtime error (a bug here); 129/130/143 need a signal
ALSO_DOCUMENTED = {"validate": {1}}  # validate --min-fit: exit 1 when a held-out fit is below
SETTINGS = settings(
    max_examples=20,  # per subcommand and per config file: ~25 s of the suite in all
    deadline=None,
    database=None,  # no .hypothesis directory; the examples are seeded by the test
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


# ------------------------------------------------------------------ the bags
@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict[str, str]:
    from mcap_ros2.writer import Writer

    d = tmp_path_factory.mktemp("bags")
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["run", "--axis", "linear", "--duration", "0.4", "--out", str(d / "run")]) == 0
    good = d / "run" / "run.mcap"
    data = bytearray(good.read_bytes())
    for pos in range(200, len(data), len(data) // 7):
        data[pos] ^= 0xFF
    (d / "corrupt.mcap").write_bytes(bytes(data))
    (d / "cut.mcap").write_bytes(good.read_bytes()[: len(data) // 2])
    with open(d / "chatter.mcap", "wb") as f:
        w = Writer(f)
        schema = w.register_msgdef("std_msgs/msg/String", "string data")
        w.write_message("/chatter", schema, {"data": "hi"}, log_time=1, publish_time=1)
        w.finish()
    (d / "text.mcap").write_text("not a bag\n")
    (d / "empty.mcap").write_bytes(b"")
    os.mkfifo(d / "fifo.mcap")  # a pipe nobody writes: read, it would block forever
    return {
        "good": str(good),
        "corrupt": str(d / "corrupt.mcap"),
        "cut": str(d / "cut.mcap"),
        "foreign": str(d / "chatter.mcap"),
        "text": str(d / "text.mcap"),
        "empty": str(d / "empty.mcap"),
        "missing": str(d / "nope.mcap"),
        "dir": str(d),
        "fifo": str(d / "fifo.mcap"),
        "device": "/dev/zero",  # read, it would never end (only read: never an output here)
    }


# -------------------------------------------------------------- strategies
ODD_NUMBERS = ["", "-0", "1e400", "0x10", "nan", "-inf", "1_000", " 5 ", "abc", "1e-9",
               "1:00", "010", "0o7", ".inf", "yes", "1e-300", "1e300"]  # fmt: skip
NUMBERISH = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=-(10**20), max_value=10**20).map(str),
    st.sampled_from(ODD_NUMBERS),
    st.text(alphabet="0123456789.-+eE,:=", min_size=1, max_size=6),
)
TEXT = st.text(min_size=0, max_size=8).filter(lambda s: "\x00" not in s)
REF_KINDS = ["sine", "smooth_step", "constant", "ramp", "waypoints", "square", ""]
REF_KEYS = ["amplitude", "frequency_hz", "offset", "target", "duration_s", "value", "slope",
            "t0_s", "file", "bogus", "kind"]  # fmt: skip
FAULTS = ["sensor_dropout", "stuck_sensor", "noise_burst", "broken_wire", "encoder_missed",
          "valve_stuck", "supply_drop", "added_mass", "controller_silent", "controller_nan",
          "meteor"]  # fmt: skip
FAULT_KEYS = ["start_s", "duration_s", "axis", "sensor", "sigma_v", "volts", "fraction",
              "factor", "mass_kg", "zap", "kind"]  # fmt: skip
# the sim card's options; never card= (it names a file to create) and never a stall long
# enough to sleep through (a valid one is a real pause of the loop)
BACKEND_KEYS = ["seed", "stall_at_s", "plant", "bogus", "kind"]
ADDRESSES = [
    "garbage",
    "tcp://",
    "tcp://127.0.0.1:99999",
    "http://127.0.0.1:8786",
    "tcp://127.0.0.1:1/x",
    "127.0.0.1",
    "tcp://:8786",
    "tls://127.0.0.1:0",
    "tcp://127.0.0.1:1",
]  # fmt: skip  (port 1: nothing listens, refused at once)
SET_KEYS = ["eso_smc.epsilon", "pid.kp", "rotary.pid.ki", "linear.td.r", "ladrc.omega_0",
            "reference.kind", "algorithm", "limits.u_max", "nope.nope", "linear", "=", ""]  # fmt: skip


def spec(kinds, keys) -> st.SearchStrategy[str]:
    pair = st.tuples(st.sampled_from(keys), st.one_of(NUMBERISH, st.sampled_from(
        ["linear", "rotary", "both", "x", "p_c1", "encoder"])))  # fmt: skip
    return st.builds(
        lambda k, pairs: k + (":" + ",".join(f"{a}={b}" for a, b in pairs) if pairs else ""),
        st.one_of(st.sampled_from(kinds), TEXT),
        st.lists(pair, max_size=3),
    )


def option_values(bags) -> dict[str, st.SearchStrategy]:
    paths = st.sampled_from([*bags.values(), ""])
    # a valid duration is kept short (a valid 500 s run would take minutes); invalid ones anything
    duration = st.one_of(
        st.floats(min_value=0.01, max_value=0.15).map(repr),
        NUMBERISH.filter(lambda v: not _is_long_valid_duration(v)),
    )
    return {
        "--duration": duration,
        "--seed": NUMBERISH,
        "--window-start": NUMBERISH,
        "--axis": st.one_of(st.sampled_from(["linear", "rotary", "both"]), TEXT),
        "--controller": st.one_of(st.sampled_from(["pid", "ladrc", "eso_smc", "fuzzy"]), TEXT),
        "--reference": spec(REF_KINDS, REF_KEYS),
        "--fault": spec(FAULTS, FAULT_KEYS),
        "--set": st.builds(lambda k, v: f"{k}={v}", st.sampled_from(SET_KEYS), NUMBERISH),
        "--plant": paths,
        "--controllers": paths,
        "--safety": paths,
        "--linear-voltage": NUMBERISH,
        "--rotary-voltage": NUMBERISH,
        "--seeds": NUMBERISH,
        "--only": st.one_of(st.sampled_from(["sine_20mm_0p25hz", "speed_800rpm"]), TEXT),
        "--config-dir": paths,
        "--algorithm": TEXT,
        # sweep: a valid example is one or two short runs in this process
        "--samples": st.one_of(
            st.integers(min_value=1, max_value=2).map(str),
            NUMBERISH.filter(lambda v: not _is_valid_int(v, 3, 10_000)),
        ),
        "--workers": NUMBERISH,
        "--experiment": st.one_of(st.sampled_from(["sine_20mm_0p25hz", "speed_800rpm"]), TEXT),
        "--gains": st.one_of(st.sampled_from(["paper", "retuned", "design"]), TEXT),
        "--rig": paths,
        "--base": paths,
        "--max-steps": NUMBERISH,
        "--level": st.one_of(st.sampled_from(["full", "quick"]), TEXT),
        "--horizon": NUMBERISH,
        "--min-fit": NUMBERISH,
        "--mode": st.one_of(st.sampled_from(["open", "closed", "auto"]), TEXT),
        "--hold": st.builds(
            lambda a, v: f"{a}={v}", st.sampled_from(["linear", "rotary", "x", "kind"]), NUMBERISH
        ),
        # the newer options: the live view alone (refused without --live), a Dask address
        # (never one that answers), the band stage's size, the sim card, the plumbing
        "--live-host": st.one_of(st.sampled_from(["0.0.0.0", "127.0.0.1", "::1"]), TEXT),
        "--live-pace": st.one_of(st.sampled_from(["fast", "realtime"]), TEXT),
        "--live-wait": NUMBERISH,
        "--address": st.one_of(st.sampled_from(ADDRESSES), TEXT.filter(lambda v: ":" not in v)),
        "--uncertainty": NUMBERISH,
        "--sampler": st.one_of(st.sampled_from(["lhs", "sobol"]), TEXT),
        "--backend": spec(["sim", "nidaqmx", "", "bogus"], BACKEND_KEYS).filter(
            lambda v: not v.startswith("nidaqmx") or ":" in v  # nidaqmx alone: the real card
        ),
        "--plumbing": st.one_of(st.sampled_from(["paper", "bidirectional"]), TEXT),
    }


def _is_valid_int(v: str, lo: int, hi: int) -> bool:
    try:
        return lo <= int(v) <= hi
    except ValueError:
        return False


def _is_long_valid_duration(v: str) -> bool:
    try:
        x = float(v)
    except ValueError:
        return False
    return 0.15 < x <= 600.0


# per subcommand: (base argv before the output, output option or None, options it takes,
# None, or the option given a refused value in every example: a valid example would run for
# minutes)
SWEEP = [
    "--samples",
    "1",
    "--reference",
    "sine:amplitude=10,frequency_hz=1",
    "--controller",
    "pid",
    "--gains",
    "retuned",
    "--executor",
    "serial",
    "--no-plots",
    "--duration",
    "0.05",
]
COMMANDS = {
    "run": (["--axis", "linear", "--controller", "pid", "--duration", "0.05"], "--out",
            ["--duration", "--seed", "--window-start", "--axis", "--controller", "--reference",
             "--fault", "--set", "--plant", "--controllers", "--safety", "--live-host",
             "--live-pace", "--live-wait"], None),
    "sim": (["--duration", "0.05", "--no-plot"], "--out",
            ["--duration", "--seed", "--linear-voltage", "--rotary-voltage", "--plant",
             "--live-pace", "--live-wait"], None),
    "analyze": (["{bag}"], None, ["--window-start"], None),
    "plot": (["{bag}"], "--out", [], None),
    "compare": (["{bag}", "{bag}"], "--out", [], None),
    "replay": (["{bag}"], "--out", ["--controller", "--axis", "--set"], None),
    "recover": (["{bag}"], "--out", [], None),
    "paper": ([], "--out", ["--seed", "--seeds", "--plant", "--config-dir", "--only",
                            "--uncertainty", "--sampler", "--address"], "--plant"),
    "tune": ([], "--out", ["--plant", "--controllers", "--axis", "--algorithm"], "--plant"),
    "sweep": (SWEEP, "--out", ["--duration", "--samples", "--seed", "--window-start",
                               "--reference", "--set", "--plant", "--workers", "--gains",
                               "--experiment", "--config-dir", "--address", "--sampler"],
              None),
    "excite": ([], "--out", ["--seed", "--axis", "--level", "--safety"], "--plant"),
    "identify": (["{bag}"], "--out", ["--axis", "--max-steps"], "--base"),
    "validate": (["{bag}"], "--out", ["--plant", "--mode", "--horizon", "--min-fit"], None),
    "rig": (["--backend", "sim:seed=1", "--axis", "linear", "--controller", "pid",
             "--duration", "0.05"], "--out",
            ["--duration", "--axis", "--reference", "--set", "--controllers", "--safety",
             "--rig", "--hold", "--backend"], None),
    "task": ([str(config_file("tasks/screw_in.yaml"))], "--out",
             ["--seed", "--plumbing", "--controllers", "--safety"], "--plant"),
    "bench": (["--quick"], None, [], "--only"),
}  # fmt: skip
EXAMPLES = {"sweep": 10, "rig": 10, "validate": 10}  # fewer: each valid one runs for ~1 s


def invoke(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with (
        contextlib.redirect_stdout(out),
        contextlib.redirect_stderr(err),
        warnings.catch_warnings(),
    ):
        warnings.simplefilter("ignore")
        rc = main(argv)
    return rc, out.getvalue(), err.getvalue()


MAX_LINE = 300  # a refusal of reasonable length, whatever was refused (paths aside)


def short(line: str) -> str:
    """``line`` with every absolute path as ``PATH`` (a user's path may be long)."""
    return re.sub(r"/[^\s',;)]+", "PATH", line)


def check(cmd: str, argv: list[str], changed: list[str], out_path: Path | None) -> int:
    rc, _, err = invoke(argv)
    assert "Traceback" not in err and "internal error" not in err, (argv, err)
    assert rc in DOCUMENTED | ALSO_DOCUMENTED.get(cmd, set()), (argv, rc, err)
    if rc == 2:
        lines = [ln for ln in err.strip().splitlines() if not ln.startswith("pneu: warning:")]
        assert len(lines) == 1, (argv, err)
        assert lines[0].startswith(f"pneu {cmd}: error: "), (argv, lines)
        assert len(short(lines[0])) <= MAX_LINE, (argv, lines[0])
        text = lines[0].lower()
        names = {c.lstrip("-").lower() for c in changed} | {c.lower() for c in changed}
        names |= {n.replace("-", "_") for n in names}
        assert any(n and n in text for n in names) or "argument" in text, (argv, changed, lines)
        if out_path is not None:
            assert not out_path.exists() or (out_path.is_dir() and not any(out_path.iterdir())), (
                argv
            )
    return rc


@st.composite
def command_line(draw, bags, cmd: str):
    base, out_opt, opts, refuse = COMMANDS[cmd]
    values = option_values(bags)
    bag_choice = st.sampled_from(list(bags))
    argv = [cmd]
    changed = []
    for tok in base:
        if tok == "{bag}":
            key = draw(bag_choice)
            argv.append(bags[key])
            if key != "good":
                changed += ["run", "runs", bags[key], Path(bags[key]).name]
        else:
            argv.append(tok)
    chosen = draw(st.lists(st.sampled_from(opts), max_size=3)) if opts else []
    for opt in chosen:
        v = draw(values[opt])
        if opt == "--address":  # with the executor it belongs to (never a local cluster)
            argv += ["--executor", "dask"]
        argv += [opt, v] if not v.startswith("-") else [f"{opt}={v}"]
        changed.append(opt)
        if opt == "--set":  # the key as the user wrote it is a field name too
            changed.append(v.partition("=")[0].strip())
        elif opt in ("--reference", "--fault"):
            kind, _, rest = v.partition(":")
            changed += [kind.strip(), *(p.partition("=")[0].strip() for p in rest.split(","))]
    if refuse == "--only":  # always one refusal: a valid example would run for minutes
        argv += ["--only", draw(TEXT.filter(lambda v: not v.startswith("-")))]
        changed.append(refuse)
    elif refuse:
        bad = draw(st.sampled_from(["corrupt", "foreign", "text", "empty", "missing", "dir",
                                    "fifo", "device"]))  # fmt: skip
        argv += [refuse, bags[bad]]
        changed.append(refuse)
    return argv, changed, out_opt


def run_example(bags, cmd, drawn) -> None:
    argv, changed, out_opt = drawn
    with tempfile.TemporaryDirectory() as tmp:
        out_path = None
        if out_opt is not None:
            suffix = {"plot": "fig.png", "replay": "new.mcap", "recover": "new.mcap",
                      "tune": "t.yaml", "identify": "p.yaml"}.get(cmd, "out")  # fmt: skip
            out_path = Path(tmp) / suffix
            argv = [*argv, out_opt, str(out_path)]
            changed = [*changed, out_opt]
        check(cmd, argv, changed, out_path)


@pytest.mark.parametrize("cmd", list(COMMANDS))
def test_generated_arguments(bags, cmd):
    @settings(SETTINGS, max_examples=EXAMPLES.get(cmd, SETTINGS.max_examples))
    @given(drawn=command_line(bags, cmd))
    def prop(drawn):
        run_example(bags, cmd, drawn)

    prop()


# ------------------------------------------------------------ config values
def leaves(tree, prefix=""):
    if isinstance(tree, dict):
        for k, v in tree.items():
            if isinstance(v, dict) and not ({"value", "unit"} <= set(v)):
                yield from leaves(v, f"{prefix}{k}.")
            else:
                yield f"{prefix}{k}"


JUNK = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.booleans(),
    st.none(),
    TEXT,
    st.lists(st.floats(allow_nan=False, allow_infinity=False), max_size=3),
    st.dictionaries(st.sampled_from(["value", "unit", "x"]), st.integers(), max_size=2),
)
FILES = {"plant.yaml": "--plant", "controllers.yaml": "--controllers", "safety.yaml": "--safety"}


@st.composite
def config_edit(draw, name: str):
    tree = yaml.safe_load(config_file(name).read_text())
    keys = list(leaves(tree))
    key = draw(st.sampled_from(keys))
    how = draw(st.sampled_from(["value", "delete", "unknown"]))
    node = tree
    parts = key.split(".")
    for p in parts[:-1]:
        node = node[p]
    leaf = parts[-1]
    if how == "delete":
        del node[leaf]
    elif how == "unknown":
        node[leaf + "_x"] = node[leaf]
        leaf = leaf + "_x"
    else:
        v = draw(JUNK)
        if name == "plant.yaml":
            node[leaf] = {**node[leaf], "value": v}
        else:
            node[leaf] = v
    return yaml.safe_dump(tree, allow_unicode=True), leaf


@pytest.mark.parametrize("name", list(FILES))
def test_generated_config_values(name):
    @SETTINGS
    @given(edit=config_edit(name))
    def prop(edit):
        text, leaf = edit
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / name
            path.write_text(text, encoding="utf-8")
            out = Path(tmp) / "out"
            argv = ["run", "--axis", "linear", "--controller", "pid", "--duration", "0.05",
                    FILES[name], str(path), "--out", str(out)]  # fmt: skip
            rc = check("run", argv, [leaf, re.sub(r"_x$", "", leaf), name], out)
            if rc == 2:
                err = invoke(argv)[2]
                assert str(path) in err  # the file is named, with line:col where known

    prop()


# ------------------------------------------------------ environment oddities
ODDITIES = ("stdout_closed", "stdout_pipe_closed", "home_unset", "lang_c")
LOCATIONS = ("plain", "spaces_non_ascii", "under_a_file", "read_only", "full")
# (argv before the output, output option and name, what a complete output holds)
ENV_COMMANDS = {
    "run": (["run", "--axis", "linear", "--controller", "pid", "--duration", "0.05"],
            "--out", "o", ("run.mcap", "metrics.json", "timeseries.npz")),
    "sim": (["sim", "--duration", "0.05"], "--out", "o", ("sim.csv", "sim.png")),
    "recover": (["recover", "{bag}"], "--out", "new.mcap", ()),
    "plot": (["plot", "{bag}"], "--out", "fig.png", ()),
    "refused": (["run", "--duration", "0", "--plant", "{plant}"], "--out", "o", ()),
}  # fmt: skip


def _limit_file_size() -> None:  # in the child: a write past 64 kB fails as on a full disk
    import resource
    import signal

    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG, not death by signal
    resource.setrlimit(resource.RLIMIT_FSIZE, (64_000, 64_000))


@st.composite
def environment(draw):
    return (
        draw(st.sampled_from(list(ENV_COMMANDS))),
        draw(st.sets(st.sampled_from(ODDITIES), max_size=2)),
        draw(st.sampled_from(LOCATIONS)),
    )


def test_environment_oddities(bags, tmp_path_factory):
    """Real processes in odd environments: no traceback, a documented exit code, at most one
    error line; a refused or failed output leaves nothing half-written (no ``.partial``),
    a finished one is whole."""
    import shutil
    import subprocess
    import sys

    plant_src = config_file("plant.yaml")

    @settings(SETTINGS, max_examples=8)
    @given(case=environment())
    # each oddity and location at least once, beside the drawn ones
    @example(case=("run", set(), "full"))  # the bag's writes fail mid-run
    @example(case=("plot", {"home_unset", "lang_c"}, "full"))
    @example(case=("sim", {"lang_c"}, "spaces_non_ascii"))  # a non-ASCII path printed
    @example(case=("refused", {"lang_c"}, "spaces_non_ascii"))  # ... in the error line
    @example(case=("sim", {"home_unset"}, "plain"))  # matplotlib without a home
    @example(case=("run", {"stdout_pipe_closed"}, "plain"))
    @example(case=("recover", {"stdout_closed"}, "read_only"))
    def prop(case):
        cmd, odd, where = case
        base, out_opt, out_name, complete = ENV_COMMANDS[cmd]
        tmp = tmp_path_factory.mktemp("env")
        d = tmp / ("dir ü 名 x" if where == "spaces_non_ascii" else "d")
        d.mkdir()
        plant = d / "plant ü.yaml"
        shutil.copy(plant_src, plant)
        out = d / out_name
        if where == "under_a_file":
            (d / "file").write_text("")
            out = d / "file" / out_name
        elif where == "read_only":
            if os.geteuid() == 0:  # root writes anywhere: a mode bit is no read-only place
                (d / "file").write_text("")
                out = d / "file" / out_name
            else:
                ro = d / "ro"
                ro.mkdir(mode=0o555)
                out = ro / out_name
        argv = [a.replace("{bag}", bags["good"]).replace("{plant}", str(plant)) for a in base]
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        if "home_unset" in odd:
            env.pop("HOME", None)
        if "lang_c" in odd:
            env.update(LANG="C", LC_ALL="C")
            env.pop("PYTHONUTF8", None)
        closed = "stdout_closed" in odd

        def pre() -> None:
            if closed:
                os.close(1)
            if where == "full":
                _limit_file_size()

        proc = subprocess.Popen(
            [sys.executable, "-m", "pneu_control.cli.main", *argv, out_opt, str(out)],
            stdout=subprocess.DEVNULL if closed else subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=env,
            cwd=d,
            preexec_fn=pre,
        )
        if "stdout_pipe_closed" in odd and proc.stdout is not None:
            proc.stdout.close()  # the reader went away (| head -0)
        if proc.stdout is not None and not proc.stdout.closed:
            _, err_b = proc.communicate(timeout=600)
        else:
            err_b = proc.stderr.read()
            proc.wait(timeout=600)
        err = err_b.decode("utf-8", "replace")
        rc = proc.returncode
        assert "Traceback" not in err and "internal error" not in err, (case, err)
        assert rc in {0, 1, 2, 3}, (case, rc, err)
        errors = [ln for ln in err.splitlines() if ": error: " in ln]
        assert len(errors) == (1 if rc in (1, 2) else 0), (case, err)
        if cmd == "refused" or where in ("under_a_file", "read_only"):
            assert rc == 2, (case, rc, err)
        elif where == "full":
            assert rc in (0, 1, 3), (case, rc, err)  # small outputs fit; a bag does not
        partials = [p for p in d.rglob("*") if p.name.endswith(".partial")]
        assert not partials, (case, partials)
        if rc in (0, 3):
            for name in complete:
                assert (out / name).is_file(), (case, name)
            if not complete:
                assert out.is_file(), case
        elif rc in (1, 2):
            held = [p for p in out.rglob("*")] if out.is_dir() else []
            assert not held or where == "full", (case, held)

    prop()
