"""``pneu sweep`` and ``pneu paper --uncertainty``: files read back by independent readers,
bad options refused in one line."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import yaml
from pneu_control.cli import main as cli
from pneu_msgs_py.params.paths import config_file

pytestmark = pytest.mark.timeout(600)

TINY = [
    "--reference", "sine:amplitude=10,frequency_hz=1.0", "--duration", "1.2",
    "--window-start", "0.4", "--controller", "pid", "--controller", "ladrc",
    "--controller", "eso_smc", "--gains", "retuned",
]  # fmt: skip


def test_pneu_sweep_writes_table_summary_and_figure(tmp_path, capsys):
    out = tmp_path / "sw"
    rc = cli.main(["sweep", "--out", str(out), "--samples", "4", "--seed", "2", *TINY])
    assert rc == 0
    with open(out / "sweep.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4 * 3
    assert {r["gains"] for r in rows} == {"retuned"}
    doc = json.loads((out / "summary.json").read_text())
    assert doc["samples"] == 4 and doc["seed"] == 2 and doc["runs"] == 12
    assert doc["executor"] == "local" and doc["sampler"] == "lhs"
    assert len(doc["factors"]) == len(rows[0]) - 14  # one column per factor
    (rank,) = doc["rankings"]  # PID, LADRC and ESO-SMC on the same samples: the paper's ranking
    assert rank["n"] == 4 and 0.0 <= rank["p_ranking"] <= 1.0
    groups = {g["controller"]: g for g in doc["groups"]}
    e = np.array([float(r["e_max"]) for r in rows if r["controller"] == "pid"])
    assert groups["pid"]["e_max"]["median"] == np.quantile(e, 0.5, method="inverted_cdf")
    env = np.load(out / "envelopes.npz")
    assert env["envelope"].shape == (12, 24) and float(env["envelope_dt_s"]) == 0.05
    png = (out / "custom__bands.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    printed = capsys.readouterr().out
    assert "P(ESO-SMC < LADRC < PID)" in printed and "| custom | ladrc | retuned |" in printed
    # the same command again: the same table, byte for byte
    rc = cli.main(["sweep", "--out", str(tmp_path / "again"), "--samples", "4", "--seed", "2",
                   "--no-plots", "--executor", "serial", *TINY])  # fmt: skip
    assert rc == 0
    assert (tmp_path / "again" / "sweep.csv").read_bytes() == (out / "sweep.csv").read_bytes()


@pytest.mark.slow
def test_pneu_paper_uncertainty_puts_bands_beside_the_figures(tmp_path):
    out = tmp_path / "paper"
    rc = cli.main(["paper", "--out", str(out), "--only", "smooth_step_eq38", "--seeds", "1",
                   "--uncertainty", "2", "--no-plots"])  # fmt: skip
    assert rc == 0
    md = (out / "paper_table.md").read_text()
    assert "## Over 2 plant samples" in md
    assert "| smooth_step_eq38 | eso_smc | paper |" in md.split("## Over")[1]
    doc = json.loads((out / "paper_table.json").read_text())
    groups = doc["uncertainty"]["groups"]
    assert [(g["controller"], g["gains"]) for g in groups] == [
        ("eso_smc", "paper"), ("eso_smc", "retuned"), ("eso_smc_plus", "design")
    ]  # fmt: skip
    g = groups[0]
    assert g["paper_e_max"] == 0.04 and g["n"] == 2
    assert g["paper_e_max_in_band"] == (g["e_max"]["q05"] <= 0.04 <= g["e_max"]["q95"])
    with open(out / "uncertainty" / "sweep.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == 2 * 3


def _error(capsys, argv):
    rc = cli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    return rc, err[-1]


@pytest.mark.parametrize(
    ("extra", "says"),
    [
        (["--samples", "0"], "pneu sweep: error: --samples: 0 refused"),
        (["--samples", "2", "--address", "tcp://127.0.0.1:1"], "--address: 'tcp://127.0.0.1:1' refused"),
        (["--samples", "2", "--workers", "0"], "--workers: 0 refused"),
        (["--samples", "2", "--gains", "best"], "gains: 'best' refused; allowed: one of paper, retuned, design"),
        (["--samples", "2", "--controller", "mpc"], "controller: 'mpc' refused"),
        (["--samples", "2", "--experiment", "sine"], "--experiment: 'sine' refused"),
    ],
)  # fmt: skip
def test_bad_options_one_line(tmp_path, capsys, extra, says):
    rc, last = _error(capsys, ["sweep", "--out", str(tmp_path), *extra])
    assert rc == 2 and says in last


def test_a_plant_file_without_ranges_is_refused(tmp_path, capsys):
    with open(config_file("plant.yaml"), encoding="utf-8") as fh:
        tree = yaml.safe_load(fh)

    def strip(node):
        for v in node.values():
            if isinstance(v, dict) and "value" in v:
                v.pop("range", None)
                v.pop("alternatives", None)
            elif isinstance(v, dict):
                strip(v)

    strip(tree)
    plant = tmp_path / "plant.yaml"
    plant.write_text(yaml.safe_dump(tree, allow_unicode=True), encoding="utf-8")
    rc, last = _error(capsys, ["sweep", "--out", str(tmp_path / "o"), "--samples", "2",
                               "--plant", str(plant), *TINY])  # fmt: skip
    assert rc == 2 and "has no range or alternatives to sweep" in last
