"""One strictness for every config file: plant, controllers, safety and rig files alike.

Each project file is edited as a user would (a syntax error, a key twice, a
typo'd key, a key deleted, a value of the wrong type or out of range) and
loaded through the command line where it has an option (``--plant``,
``--controllers``, ``--safety``, ``PNEU_CONFIG_DIR``, ``paper --config-dir``,
``tune --controllers``), else through its loader: one line, ``file:line:col``,
the key as written (after the option the file came from), exit code 2, nothing written.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from pneu_control.cli.main import main
from pneu_driver.daq.rig import load_rig_params
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.paths import config_file

# (file, option, text edit (old, new), what the one line must contain)
EDITS = {
    "syntax": ("key: [1, 2", r"{f}:\d+:\d+: .*expected"),
    "duplicate": (None, r"{f}:(\d+):\d+: key '(\w+)' given twice \(first at line \d+\)"),
    "unknown": (None, r"{f}:\d+:\d+: [\w.]*typo_key: .* refused; allowed: no such parameter"),
    "missing": (None, r"{f}:\d+:\d+: [\w.]+: missing; required: "),
    "wrong_type": (None, r"{f}:\d+:\d+: [\w.]+: 'fast' refused; allowed: "),
}
FILES = {
    "plant.yaml": ("--plant", "  M: {value: 0.28", "  M: {value: fast"),
    "controllers.yaml": ("--controllers", "      kp: 0.38", "      kp: fast"),
    "safety.yaml": ("--safety", "watchdog_ms: 50.0 ", "watchdog_ms: fast "),
    "rig.yaml": (None, "p_atm_pa: 101325.0", "p_atm_pa: fast"),
}


def edited(name: str, kind: str, tmp: Path) -> Path:
    text = config_file(name).read_text(encoding="utf-8")
    lines = text.splitlines(keepends=True)
    first = next(i for i, ln in enumerate(lines) if re.match(r"^\s*\w+:", ln))
    key_line = next(i for i, ln in enumerate(lines) if re.match(r"^\s*\w+: [^#\s]", ln))
    if kind == "syntax":
        lines.insert(first + 1, "key: [1, 2\n")
    elif kind == "duplicate":
        lines.insert(key_line + 1, lines[key_line])
    elif kind == "unknown":
        indent = re.match(r"^(\s*)", lines[key_line]).group(1)
        value = "{value: 1.0, unit: '-', source: x}" if name == "plant.yaml" else "1.0"
        lines.insert(key_line + 1, f"{indent}typo_key: {value}\n")
    elif kind == "missing":
        del lines[key_line]
    elif kind == "wrong_type":
        _, old, new = FILES[name]
        text = "".join(lines)
        assert old in text, (name, old)
        lines = [text.replace(old, new, 1)]
    p = tmp / name
    p.write_text("".join(lines), encoding="utf-8")
    return p


def load_via_cli(name: str, path: Path, tmp: Path, capsys) -> str:
    option = FILES[name][0]
    out = tmp / "out"
    if option is None:
        with pytest.raises(ParamError) as err:
            load_rig_params(path)
        return str(err.value)
    capsys.readouterr()
    assert main(["run", "--duration", "0.1", option, str(path), "--out", str(out)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert not out.exists()
    assert lines[0].startswith("pneu run: error: ")
    return lines[0][len("pneu run: error: ") :]


@pytest.mark.parametrize("kind", list(EDITS))
@pytest.mark.parametrize("name", list(FILES))
def test_every_config_file_refuses_the_same_mistakes_the_same_way(name, kind, tmp_path, capsys):
    path = edited(name, kind, tmp_path)
    msg = load_via_cli(name, path, tmp_path, capsys)
    option = FILES[name][0]
    pattern = (f"{option}: " if option else "") + EDITS[kind][1].format(f=re.escape(str(path)))
    m = re.match(pattern, msg)
    assert m, msg
    assert "\n" not in msg
    if kind == "duplicate":  # the line named is the second occurrence
        line = int(m.group(1))
        assert path.read_text().splitlines()[line - 1].strip().startswith(m.group(2))


def test_the_project_files_are_complete_and_load(tmp_path):
    from pneu_control.controller.params import load_controller_params
    from pneu_driver.safety import load_safety_params
    from pneu_sim.physics.plant_file import load_plant

    load_plant()
    load_safety_params()
    load_rig_params()
    for f in ("controllers.yaml", "controllers_retuned.yaml"):
        for axis in ("linear", "rotary"):
            load_controller_params(axis, config_file(f))


def test_the_valve_chart_in_controllers_yaml_is_the_twins(tmp_path):
    from pneu_control.algorithms.eso_smc_plus_params import MPYE_DU_V, MPYE_FLOW
    from pneu_control.controller.params import load_controller_params

    for axis in ("linear", "rotary"):
        p = load_controller_params(axis).eso_smc_plus
        assert p.valve_du_table == tuple(MPYE_DU_V) and p.valve_flow_table == tuple(MPYE_FLOW)


def test_every_way_a_broken_controllers_file_arrives_is_one_line(tmp_path, capsys, monkeypatch):
    cfg = tmp_path / "cfg"
    shutil.copytree(config_file("plant.yaml").parent, cfg)
    (cfg / "controllers.yaml").write_text("linear_controller:\n  ros__parameters: [\n")
    expected = f"{cfg / 'controllers.yaml'}:3:1: "
    for argv in (
        ["paper", "--config-dir", str(cfg), "--out", str(tmp_path / "p")],
        ["tune", "--controllers", str(cfg / "controllers.yaml"), "--out", str(tmp_path / "t.yaml")],
    ):
        capsys.readouterr()
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and expected in err[0], err
    monkeypatch.setenv("PNEU_CONFIG_DIR", str(cfg))
    capsys.readouterr()
    assert main(["run", "--duration", "0.1", "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0], err
    assert not any((tmp_path / d).exists() for d in ("p", "t.yaml", "r"))
