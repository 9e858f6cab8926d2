"""Output claims: checked first, locked, never an input, temporary names renamed when complete."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest
from pneu_msgs_py.lifecycle.duration import MAX_DURATION_S, MIN_DURATION_S, check_duration
from pneu_msgs_py.lifecycle.outputs import LOCK_NAME, OutputDir, OutputFile
from pneu_msgs_py.params.core import ParamError

ART = ("run.mcap", "metrics.json")


def test_new_directory_claimed_written_under_partial_names_and_published(tmp_path):
    out = tmp_path / "a" / "b"
    claim = OutputDir(out, ART).check()
    assert not out.exists()  # checking creates nothing
    with claim:
        assert (out / LOCK_NAME).exists()
        claim.partial("metrics.json").write_text("{}")
        assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME, "metrics.json.partial"]
        claim.publish("metrics.json")
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json"]  # lock file gone


def test_non_empty_directory_refused_unless_overwrite_which_replaces_only_its_artefacts(tmp_path):
    (tmp_path / "run.mcap").write_text("old bag")
    (tmp_path / "metrics.json.partial").write_text("killed")
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(ParamError, match=r"^--out: .* refused; allowed: a new or empty directory"):
        OutputDir(tmp_path, ART).check()
    with OutputDir(tmp_path, ART, overwrite=True):
        assert sorted(p.name for p in tmp_path.iterdir()) == [LOCK_NAME, "notes.txt"]
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_an_output_that_is_an_input_is_refused_even_with_overwrite(tmp_path):
    bag = tmp_path / "run.mcap"
    bag.write_text("x")
    with pytest.raises(ParamError, match="not one of the command's inputs"):
        OutputFile(bag, overwrite=True, inputs=[bag]).check()
    with pytest.raises(ParamError, match="not inputs of the command"):
        OutputDir(tmp_path, ART, overwrite=True, inputs=[str(bag)]).check()
    link = tmp_path / "link.mcap"
    link.symlink_to(bag)
    with pytest.raises(ParamError, match="inputs"):
        OutputFile(link, overwrite=True, inputs=[bag]).check()


def test_file_claims(tmp_path):
    f = tmp_path / "fig.png"
    with pytest.raises(ParamError, match="ending in .png"):
        OutputFile(tmp_path / "fig", suffixes=(".png",)).check()
    with pytest.raises(ParamError, match="a file name"):
        OutputFile(tmp_path, suffixes=(".png",)).check()
    with OutputFile(f) as claim:
        claim.partial.write_text("png")
        claim.publish()
    with pytest.raises(ParamError, match="a new file, or --overwrite"):
        OutputFile(f).check()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig.png"]


_HOLD = textwrap.dedent(
    """
    import sys, time
    from pneu_msgs_py.lifecycle.outputs import OutputDir
    with OutputDir(sys.argv[1], ("run.mcap",)):
        print("held", flush=True)
        time.sleep(60)
    """
)


def test_a_second_process_on_the_same_output_is_refused_at_once(tmp_path):
    out = tmp_path / "run"
    holder = subprocess.Popen(
        [sys.executable, "-c", _HOLD, str(out)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(ParamError, match="no other pneu command is writing"):
            with OutputDir(out, ("run.mcap",)):
                pass
    finally:
        holder.kill()
        holder.wait()
    # the holder was killed: its lock file stays, but nobody holds it
    with OutputDir(out, ("run.mcap",)):
        pass


def test_discard_leaves_nothing_behind(tmp_path):
    out = tmp_path / "new" / "run"
    with OutputDir(out, ART) as claim:
        claim.partial("run.mcap").write_text("half")
        claim.discard()
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize(
    "bad", [0.0, 0.009, 600.001, 1e12, float("nan"), float("inf"), -1, "5", True]
)
def test_one_duration_cap(bad):
    with pytest.raises(ParamError, match=r"^--duration: .* allowed: .*\[0.01, 600\] s"):
        check_duration(bad)
    assert check_duration(MIN_DURATION_S) == 0.01 and check_duration(MAX_DURATION_S) == 600.0
