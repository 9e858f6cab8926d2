"""Acceptance: `pneu paper` rows are reproduced exactly by `pneu analyze --json` on its bags;
bad bags give one line and a non-zero exit."""

import json
import struct

import pytest
from pneu_control.cli.main import main


@pytest.fixture(scope="module")
def paper_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("paper")
    argv = ["paper", "--out", str(out), "--only", "smooth_step_eq38", "--no-plots", "--seeds", "2"]
    assert main(argv) == 0
    return out


def test_paper_table_fields(paper_dir):
    doc = json.loads((paper_dir / "paper_table.json").read_text())
    rows = doc["experiments"]
    assert {r["gains"] for r in rows} == {"paper", "paper_abs", "retuned", "design"}
    assert {r["controller"] for r in rows} == {"eso_smc", "eso_smc_plus"}
    for r in rows:
        assert r["seeds"] == 2 and r["e_max_worst"] >= r["e_max_mean"]
        assert r["e_max_worst"] >= r["e_max"] and r["rmse_worst"] >= r["rmse"]  # seed 0 included
        assert r["id"] == "smooth_step_eq38" and r["axis"] == "linear" and r["unit"] == "mm"
        paper_e_max = 0.04 if r["controller"] == "eso_smc" else None
        assert r["paper_e_max"] == paper_e_max and r["paper_rmse"] is None
        assert r["window_s"][0] == 5.0
    assert "| smooth_step_eq38 | eso_smc | paper |" in (paper_dir / "paper_table.md").read_text()


def test_analyze_json_reproduces_each_row_exactly(paper_dir, capsys):
    rows = json.loads((paper_dir / "paper_table.json").read_text())["experiments"]
    for r in rows:
        capsys.readouterr()
        assert main(["analyze", str(paper_dir / r["run_dir"] / "run.mcap"), "--json"]) == 0
        got = json.loads(capsys.readouterr().out)["metrics"][r["axis"]]
        assert got["e_max"] == r["e_max"] and got["rmse"] == r["rmse"]
        assert got["window_s"] == r["window_s"]


def _one_line_error(capsys, argv, needle):
    capsys.readouterr()
    rc = main(argv)
    err = capsys.readouterr().err.strip()
    assert rc != 0
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert needle in err
    return err


def test_bad_bags_one_line_errors(paper_dir, tmp_path, capsys):
    good = paper_dir / "smooth_step_eq38__eso_smc__paper" / "run.mcap"
    not_mcap = tmp_path / "notes.mcap"
    not_mcap.write_text("hello, not a bag\n")
    _one_line_error(capsys, ["analyze", str(not_mcap)], str(not_mcap))
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    _one_line_error(capsys, ["analyze", str(empty)], str(empty))
    _one_line_error(capsys, ["analyze", str(tmp_path / "missing.mcap")], "missing.mcap")
    # an MCAP whose profile is not ros2
    data = bytearray(good.read_bytes())
    i = data.index(b"ros2")
    data[i : i + 4] = b"xxxx"
    other = tmp_path / "other_profile.mcap"
    other.write_bytes(bytes(data))
    _one_line_error(capsys, ["analyze", str(other)], str(other))
    # a header-only file: magic + header record, nothing else
    head = bytes(good.read_bytes()[:8])
    (tmp_path / "magic.mcap").write_bytes(head + struct.pack("<BQ", 1, 0))
    _one_line_error(capsys, ["analyze", str(tmp_path / "magic.mcap")], "magic.mcap")


def test_truncated_bag_yields_complete_chunks_with_warning(paper_dir, tmp_path, capsys):
    good = paper_dir / "smooth_step_eq38__eso_smc__paper" / "run.mcap"
    data = good.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    capsys.readouterr()
    rc = main(["analyze", str(cut), "--window-start", "0.5"])
    out = capsys.readouterr()
    assert rc == 0
    assert "truncated" in (out.out + out.err)
    assert "linear" in out.out


def test_bag_missing_controller_topic(tmp_path, capsys):
    from pneu_msgs_py.bag import BagWriter
    from pneu_msgs_py.contract.samples import SensorSample

    path = tmp_path / "sensors_only.mcap"
    with BagWriter(path) as w:
        for k in range(10):
            w.write_sample(SensorSample(k, k * 1_000_000, 2e5, 2e5, 1e5, 0.0, 0.0, 0.0, 0))
    _one_line_error(capsys, ["analyze", str(path)], "controller_state")
