"""`pneu sim`: files written, numbers printed, bad input refused in one line."""

import argparse
import csv

import numpy as np
import pytest
import yaml
from pneu_msgs_py.params.paths import config_file
from pneu_sim.cli import sim as cli_sim


def parse(argv):
    p = argparse.ArgumentParser(prog="pneu sim")
    cli_sim.add_arguments(p)
    return p.parse_args(argv)


def test_writes_csv_and_png_and_prints_numbers(tmp_path, capsys):
    args = parse(
        [
            "--duration",
            "0.6",
            "--linear-voltage",
            "6",
            "--rotary-voltage",
            "7",
            "--out",
            str(tmp_path),
            "--seed",
            "3",
        ]
    )
    assert cli_sim.run(args) == 0
    out = capsys.readouterr().out
    assert "end position:" in out and "mm" in out
    assert "steady speed:" in out and "rpm" in out
    with open(tmp_path / "sim.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert tuple(rows[0]) == cli_sim.CSV_COLUMNS
    data = np.array(rows[1:], dtype=float)
    assert data.shape == (601, len(cli_sim.CSV_COLUMNS))
    t = data[:, 0]
    assert np.allclose(np.diff(t), 1e-3)
    assert np.all(np.diff(data[:, 10]) >= -1e-12)  # 6 V extends the piston
    assert data[-1, 11] > 100  # the motor turns at 7 V
    png = (tmp_path / "sim.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    x_end = 1e3 * data[-100:, 6].mean()
    assert f"end position: {x_end:.2f} mm" in out


@pytest.mark.parametrize(
    "argv",
    [
        ["--duration", "abc"],
        ["--linear-voltage", "11"],
        ["--rotary-voltage", "-0.5"],
        ["--seed", "x"],
        [],  # --out is required
    ],
)
def test_bad_options_exit_with_usage(argv, tmp_path, capsys):
    if argv:
        argv = [*argv, "--out", str(tmp_path)]
    with pytest.raises(SystemExit) as err:
        parse(argv)
    assert err.value.code == 2
    assert "usage:" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "field", "allowed"),
    [
        (["--duration", "-1"], "--duration", "[0.01, 600] s"),
        (["--duration", "1e9"], "--duration", "[0.01, 600] s"),
        (["--seed", "-2"], "--seed", "[0, 4294967295]"),
    ],
)
def test_bad_values_are_one_line_naming_the_option(argv, field, allowed, tmp_path, capsys):
    from pneu_control.cli.main import main

    assert main(["sim", *argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"pneu sim: error: {field}:") and allowed in err[0]
    assert not (tmp_path / "o").exists()  # refused before anything was written


def test_bad_plant_file_is_one_line_error(tmp_path):
    with open(config_file("plant.yaml"), encoding="utf-8") as fh:
        tree = yaml.safe_load(fh)
    tree["linear"]["V_1d"]["value"] = 0.0
    bad = tmp_path / "plant.yaml"
    bad.write_text(yaml.safe_dump(tree), encoding="utf-8")
    args = parse(["--out", str(tmp_path / "o"), "--plant", str(bad), "--no-plot"])
    with pytest.raises(
        ValueError,
        match=r"plant\.yaml:\d+:\d+: linear\.V_1d: 0\.0 refused; allowed: \(0, 0\.001\] m\^3$",
    ):
        cli_sim.run(args)
