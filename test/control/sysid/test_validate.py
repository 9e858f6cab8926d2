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
    assert closed.mode == "closed" and opened.mode == "open, restarted every 1 s"
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
    # the rotary axis of this linear run: not validated, and why
    assert opened.axes["rotary"].reason == "not in this bag (no valve commands recorded)"


def test_cli_report_and_figures(run_bag, tmp_path, capsys):
    assert main(["validate", str(run_bag), "--out", str(tmp_path), "--min-fit", "50"]) == 0
    text = capsys.readouterr().out
    assert "| fit x %" in text and "yes" in text  # a bag identify did not use: held out
    doc = json.loads((tmp_path / "validate.json").read_text())
    assert doc[0]["held_out"] is True and doc[0]["fit_percent"]["x"] > 95.0
    tag = run_bag.parent.name
    assert sorted(p.name for p in tmp_path.glob("*.png")) == [
        f"validate_00_{tag}_linear.png", f"validate_00_{tag}_rotary.png"
    ]  # fmt: skip
    assert "rotary not validated: not in this bag (no valve commands recorded)" in text
    assert main(["validate", str(run_bag), "--min-fit", "99.99"]) == 1


@pytest.fixture(scope="module")
def both_bag(tmp_path_factory):
    """A quick excitation of both axes on the nominal twin."""
    out = tmp_path_factory.mktemp("both")
    argv = ["excite", "--axis", "both", "--level", "quick", "--seed", "5", "--hide-plant"]
    assert main([*argv, "--out", str(out)]) == 0
    return out / "run.mcap"


SIGNALS = ("x", "p_c1", "p_c2", "p_m1", "omega")
HORIZONS = ("0.2", "1", "5", "inf")


def test_both_axes_of_a_both_axes_bag_at_every_horizon(both_bag):
    """Every axis validated at every horizon; on its own twin the fit is what the noise leaves,
    whatever the horizon: the fit judges the twin, not the method."""
    from pneu_sim.physics.plant_file import load_plant

    v = validate_record(load_record(both_bag), load_plant())
    assert all(av.validated for av in v.axes.values())
    assert v.headline == "1" and set(v.fits) == set(SIGNALS)
    for name in SIGNALS:
        axis = "linear" if name in ("x", "p_c1", "p_c2") else "rotary"
        fits = [v.axes[axis].fits[h][name] for h in HORIZONS]
        assert min(fits) > 85.0, (name, fits)
        assert max(fits) - min(fits) < 2.0, (name, fits)
    # one offset per pressure sensor, inside the Huba 511's band (±0.5 % FS = 5 kPa)
    assert set(v.offsets) == {"p_c1", "p_c2", "p_m1"}
    assert all(abs(o) <= 5.0e3 for o in v.offsets.values())
    assert v.warnings == []  # its own twin: no structural mismatch
    for av in v.axes.values():  # the residual is the sensor noise, and white
        for sd in av.diagnostics.signals.values():
            if sd.signal != "omega":
                assert sd.noise_share > 0.8, (sd.signal, sd.rms, sd.noise_sigma)


def test_an_axis_is_validated_on_its_valid_stretches_or_says_why_not(both_bag):
    """A supervisor event half-way: the rotary axis is still validated (the pure simulation
    runs up to it); a lost sample cuts the cylinder's pure simulation in two stretches; an axis
    without valid data gets one line saying so."""
    from pneu_sim.physics.plant_file import load_plant

    plant = load_plant()
    rec = load_record(both_bag)
    i = rec.n // 2
    rec.valid["rotary"][i:] = False
    rec.notes.append(f"rotary: supervisor event at sample {i}: data after it not used")
    rec.y["x"][7000] = math.nan
    v = validate_record(rec, plant, horizons=(1.0, math.inf))
    rot, lin = v.axes["rotary"], v.axes["linear"]
    assert rot.validated and lin.validated
    assert rot.notes == [f"rotary: supervisor event at sample {i}: data after it not used"]
    sim = rot.yhat["inf"]["omega"]
    assert np.isnan(sim[i:]).all() and np.isfinite(sim[100 : i - 20]).all()
    lin_sim = lin.yhat["inf"]["x"]
    assert np.isfinite(lin_sim[100:7000]).all() and np.isfinite(lin_sim[7012:9000]).all()
    assert np.isnan(lin_sim[7000:7012]).all()  # the lost sample, the next start's line fit
    rec.valid["rotary"][:] = False
    v = validate_record(rec, plant, horizons=(1.0,))
    assert v.axes["rotary"].reason == (
        f"no valid data (rotary: supervisor event at sample {i}: data after it not used)"
    )
    assert set(v.fits) == {"x", "p_c1", "p_c2"}


def test_cli_shows_every_axis_and_horizon(both_bag, tmp_path, capsys):
    assert main(["validate", str(both_bag), "--out", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    rows = [line for line in text.splitlines() if line.startswith(f"| {both_bag} |")]
    assert [r.split(" | ")[2] for r in rows] == ["0.2 s", "1 s (judged)", "5 s", "whole stretches"]
    assert not any("—" in r for r in rows)  # both axes, every signal
    assert "not validated" not in text and "structural mismatch" not in text
    doc = json.loads((tmp_path / "validate.json").read_text())[0]
    assert doc["headline"] == "1" and doc["structural_mismatch"] == []
    for axis in ("linear", "rotary"):
        a = doc["axes"][axis]
        assert a["validated"] and set(a["fit_percent"]) == set(HORIZONS)
        assert a["figure"].endswith(f"_{axis}.png") and a["diagnostics"]["warning"] == ""
    assert len(list(tmp_path.glob("*.png"))) == 2
