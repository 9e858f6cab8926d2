"""The in-process runner: one-sample delay, determinism, bag ↔ analysis equality."""

import json

import numpy as np
import pytest
from pneu_control.analysis.run_analysis import analyze
from pneu_control.experiment import session
from pneu_control.experiment.runner import RunSpec, run
from pneu_sim.physics.plant_file import load_plant


@pytest.fixture(scope="module")
def plant():
    return load_plant()


def _spec(
    plant,
    axis="linear",
    controller="pid",
    duration=3.0,
    seed=0,
    ref="sine:amplitude=10,frequency_hz=1.0",
):
    return session.build_spec(
        axes=(axis,),
        controller=controller,
        reference=ref,
        duration_s=duration,
        seed=seed,
        plant=plant,
    )


def test_one_sample_transport_delay(plant):
    """u_k answers sample k and reaches the plant only over [k+1, k+2)."""
    from pneu_sim.physics.plant import Plant

    spec = _spec(plant, duration=0.2)
    res = run(spec)
    u = res.axes["linear"]["u"]
    # replay the recorded commands open loop with the documented delay: same samples
    p = Plant(plant, seed=spec.seed)
    s = p.reset()
    xs = [s.x]
    held = 5.0
    for k in range(len(u) - 1):
        s = p.step(held, 5.0)
        held = u[k]
        xs.append(s.x)
    assert np.array_equal(np.array(xs), res.samples["x"])


def test_same_seed_same_bytes_other_seed_differs(plant, tmp_path):
    a = session.execute(_spec(plant, seed=3), tmp_path / "a", bag=False)
    b = session.execute(_spec(plant, seed=3), tmp_path / "b", bag=False)
    c = session.execute(_spec(plant, seed=4), tmp_path / "c", bag=False)
    assert (tmp_path / "a/metrics.json").read_bytes() == (tmp_path / "b/metrics.json").read_bytes()
    assert (tmp_path / "a/timeseries.npz").read_bytes() == (
        tmp_path / "b/timeseries.npz"
    ).read_bytes()
    assert a.metrics["linear"].rmse == b.metrics["linear"].rmse != c.metrics["linear"].rmse


def test_metrics_json_echoes_config_and_units(plant, tmp_path):
    session.execute(_spec(plant, ref="sine:amplitude=10,frequency_hz=0.5"), tmp_path, bag=False)
    doc = json.loads((tmp_path / "metrics.json").read_text())
    assert doc["units"] == {"linear": "mm", "rotary": "rpm"}
    assert doc["config"]["controllers"]["linear"]["reference"]["amplitude"] == 10.0
    assert doc["metrics"]["linear"]["window_s"][0] == pytest.approx(4.0)  # 2 periods of 0.5 Hz


def test_analysis_of_the_bag_reproduces_runner_metrics_exactly(plant, tmp_path):
    res = session.execute(
        _spec(plant, duration=2.5, ref="sine:amplitude=10,frequency_hz=1.0"), tmp_path
    )
    ana = analyze(tmp_path / "run.mcap")
    assert ana.metrics["linear"] == res.metrics["linear"]  # bit for bit
    assert ana.traces["linear"].algorithm == "pid"
    assert np.array_equal(ana.traces["linear"].u, res.axes["linear"]["u"])


def test_interrupted_run_leaves_a_readable_bag(plant, tmp_path, monkeypatch):
    calls = {"n": 0}

    def progress(t):
        calls["n"] += 1
        if t >= 1.0:
            raise KeyboardInterrupt

    from pneu_control.experiment import bag_log

    spec = _spec(plant, duration=5.0)
    with bag_log.open_run_bag(tmp_path / "run.mcap", spec, session.config_echo(spec)) as w:
        res = run(spec, bag=w, progress=progress)
    assert res.interrupted and 1.0 <= res.t[-1] < 1.1
    ana = analyze(tmp_path / "run.mcap")
    assert len(ana.traces["linear"].t) == len(res.t)


def test_bad_spec_refused(plant):
    with pytest.raises(ValueError, match="duration"):
        RunSpec(axes=("linear",), controllers={"linear": None}, plant=plant, duration_s=-1.0)
    with pytest.raises(ValueError, match="axis"):
        RunSpec(axes=("vertical",), controllers={}, plant=plant, duration_s=1.0)
    with pytest.raises(ValueError, match="epsilon"):
        session.build_spec(axes=("linear",), sets=["eso_smc.epsilon=-1"], plant=plant)
    with pytest.raises(ValueError, match="--set"):
        session.build_spec(axes=("linear",), sets=["nonsense"], plant=plant)
