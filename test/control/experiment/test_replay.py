"""Open-loop replay: same controller on the same samples gives the recorded commands."""

import numpy as np
import pytest
from pneu_control.analysis.run_analysis import analyze
from pneu_control.cli.main import main
from pneu_control.experiment import session
from pneu_control.experiment.replay import replay
from pneu_msgs_py.bag.reader import read_run
from pneu_sim.physics.plant_file import load_plant


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec")
    spec = session.build_spec(
        axes=("linear", "rotary"),
        controller="eso_smc",
        controllers_file=None,
        sets=[
            "linear.reference.kind=sine",
            "linear.reference.frequency_hz=1.0",
            "rotary.reference.kind=constant",
            "rotary.reference.value=600.0",
        ],
        duration_s=1.5,
        plant=load_plant(),
    )
    session.execute(spec, out)
    return out / "run.mcap"


def test_replay_with_recorded_params_reproduces_commands(recorded, tmp_path):
    replay(recorded, tmp_path / "re.mcap")
    a, b = analyze(recorded), analyze(tmp_path / "re.mcap")
    for axis in ("linear", "rotary"):
        assert np.array_equal(a.traces[axis].u, b.traces[axis].u)
        assert np.array_equal(a.traces[axis].state["z3"], b.traces[axis].state["z3"])


def test_replay_with_new_gains_differs_and_says_open_loop(recorded, tmp_path):
    out = tmp_path / "re.mcap"
    replay(recorded, out, axes=["linear"], overrides={"linear": {"eso_smc.omega_0": 60.0}})
    data = read_run(out)
    assert data.metadata["pneu.run"]["open_loop"] == "true"
    a, b = analyze(recorded), analyze(out)
    assert not np.array_equal(a.traces["linear"].state["z2"], b.traces["linear"].state["z2"])
    # the sensor stream is the recorded one, untouched
    assert np.array_equal(a.traces["linear"].measured, b.traces["linear"].measured)


def test_replay_cli_rejects_bad_gain_in_one_line(recorded, tmp_path, capsys):
    rc = main(
        [
            "replay",
            str(recorded),
            "--set",
            "eso_smc.omega_0=-3.0",
            "--out",
            str(tmp_path / "x.mcap"),
        ]
    )
    err = capsys.readouterr().err
    assert (
        rc == 2
        and "omega_0" in err
        and "Traceback" not in err
        and len(err.strip().splitlines()) == 1
    )
