"""pneu validate: MATLAB compare's fit, the open- and closed-loop replays, the report."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from pneu_control.cli.main import main
from pneu_control.sysid.record import load_record
from pneu_control.sysid.validate import fit_percent, validate_record


def test_fit_percent_is_the_nrmse_fit():
    t = np.linspace(0.0, 1.0, 1001)
    y = np.sin(2 * np.pi * t)
    assert fit_percent(y, y) == 100.0
    assert fit_percent(y, np.full_like(y, y.mean())) == pytest.approx(0.0, abs=1e-12)
    yhat = y + 0.1 * np.cos(7 * t)
    expect = 100.0 * (
        1.0 - math.sqrt(np.sum((y - yhat) ** 2)) / math.sqrt(np.sum((y - y.mean()) ** 2))
    )
    assert fit_percent(y, yhat) == pytest.approx(expect, rel=1e-12)
    assert fit_percent(y, -y) < 0.0  # worse than the mean: negative, as compare reports it


@pytest.fixture(scope="module")
def run_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    argv = [
        "run",
        "--axis",
        "linear",
        "--controller",
        "pid",
        "--reference",
        "sine:amplitude=15,frequency_hz=0.5",
    ]
    assert main([*argv, "--duration", "4", "--seed", "3", "--out", str(out)]) == 0
    return out / "run.mcap"


def test_a_run_replays_closed_and_open_loop_on_its_own_twin(run_bag):
    from pneu_sim.physics.plant_file import load_plant

    rec = load_record(run_bag)
    plant = load_plant()
    closed = validate_record(rec, plant, mode="closed")
    opened = validate_record(rec, plant, mode="open")
    assert closed.mode == "closed" and opened.mode == "open"
    for v in (closed, opened):
        assert set(v.fits) == {"x", "p_c1", "p_c2"}
        assert v.fits["x"] > 95.0, v.fits
        assert min(v.fits.values()) > 80.0, v.fits
        # the pressure sensors' offsets (±0.5 % FS, drawn from the seed) are found and removed
        assert all(abs(o) < 6e3 for o in v.offsets.values())
    # a wrong twin fits worse
    from pneu_msgs_py.params.core import with_updates

    wrong = with_updates(plant, {"valve_linear.Q_n": 0.5 * plant.valve_linear.Q_n})
    assert validate_record(rec, wrong, mode="open").fits["x"] < opened.fits["x"] - 5.0


def test_cli_report_and_figures(run_bag, tmp_path, capsys):
    assert main(["validate", str(run_bag), "--out", str(tmp_path), "--min-fit", "50"]) == 0
    text = capsys.readouterr().out
    assert "| fit x %" in text and "yes" in text  # a bag identify did not use: held out
    doc = json.loads((tmp_path / "validate.json").read_text())
    assert doc[0]["held_out"] is True and doc[0]["fit_percent"]["x"] > 95.0
    assert len(list(tmp_path.glob("*.png"))) == 1
    assert main(["validate", str(run_bag), "--min-fit", "99.99"]) == 1
