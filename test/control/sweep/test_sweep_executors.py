"""A sweep's table: the same bytes for the same seed, on every executor (this process,
local spawn processes, a Dask cluster started inside the test), and each row equal to
the runner's own result for the plant written in it."""

import csv
import io

import numpy as np
import pytest
from pneu_control.experiment import session
from pneu_control.experiment.runner import run
from pneu_control.sweep.engine import custom_experiment, plan_sweep, run_sweep
from pneu_control.sweep.table import RUN_COLUMNS, table_text
from pneu_msgs_py.params.core import with_updates
from pneu_msgs_py.params.paths import config_file
from pneu_sim.physics.plant_file import load_plant

pytestmark = pytest.mark.timeout(600)


def _plan(seed=5):
    exp = custom_experiment(
        axis="linear",
        reference="sine:amplitude=10,frequency_hz=1.0",
        duration_s=1.2,
        window_start_s=0.4,
    )
    return plan_sweep(
        samples=3,
        seed=seed,
        experiments=[exp],
        controllers=["pid", "eso_smc"],
        gains=["retuned"],
    )


def _text(result):
    return table_text(result.rows, result.plan.points, result.factor_names)


@pytest.fixture(scope="module")
def serial():
    return run_sweep(_plan(), executor="serial")


def test_same_seed_same_bytes_other_seed_other(serial):
    again = run_sweep(_plan(), executor="serial")
    assert _text(again) == _text(serial)
    other = run_sweep(_plan(seed=6), executor="serial")
    assert _text(other) != _text(serial)


def test_table_is_tidy_csv(serial):
    rows = list(csv.DictReader(io.StringIO(_text(serial))))
    assert len(rows) == 3 * 2  # samples × (pid, eso_smc)
    assert list(rows[0])[: len(RUN_COLUMNS)] == list(RUN_COLUMNS)
    assert [(r["sample"], r["controller"]) for r in rows] == [
        (str(s), c) for s in range(3) for c in ("pid", "eso_smc")
    ]
    assert {r["seed"] for r in rows} == {"5", "6", "7"}  # seed + sample
    for r in rows:
        assert r["unit"] == "mm" and float(r["e_max"]) > 0.0 and r["safety_trip"] == ""
        assert 0.7 * 0.28 <= float(r["linear.M"]) <= 1.1 * 0.28 + 1e-12
        assert r["supply[gauge|absolute]"] in ("gauge", "absolute")


def test_each_row_is_the_runner_on_the_plant_it_names(serial):
    """Rebuild one run from its CSV row alone and run today's runner on it."""
    row = list(csv.DictReader(io.StringIO(_text(serial))))[3]  # sample 1, eso_smc
    nominal = load_plant()
    updates = {}
    for key, text in row.items():
        if key in RUN_COLUMNS:
            continue
        if key == "supply[gauge|absolute]":
            gauge = text == "gauge"
            updates["supply.p_s_linear"] = 301325.0 if gauge else 200000.0
            updates["supply.p_s_rotary"] = 501325.0 if gauge else 400000.0
        else:
            updates[key] = float(text)
    plant = with_updates(nominal, updates)
    spec = session.build_spec(
        axes=("linear",),
        controller="eso_smc",
        reference="sine:amplitude=10,frequency_hz=1.0",
        duration_s=1.2,
        seed=int(row["seed"]),
        controllers_file=config_file("controllers_retuned.yaml"),
        plant=plant,
        window_start_s=0.4,
    )
    m = run(spec).metrics["linear"]
    assert repr(m.e_max) == row["e_max"] and repr(m.rmse) == row["rmse"]
    assert plant != nominal


def test_local_processes_give_the_same_table(serial):
    local = run_sweep(_plan(), executor="local", workers=2)
    assert _text(local) == _text(serial)
    for a, b in zip(local.rows, serial.rows):
        np.testing.assert_array_equal(a.envelope, b.envelope)


def test_dask_cluster_gives_the_same_table(serial):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=None,
    ) as cluster:
        # through the scheduler's address, as `pneu sweep --executor dask --address` does
        on_dask = run_sweep(
            _plan(), executor="dask", address=cluster.scheduler_address, timeout_s=300
        )
    assert on_dask.executor == "dask"
    assert _text(on_dask) == _text(serial)


def test_rows_come_back_in_task_order_whatever_finished_first(serial):
    plan = _plan()
    plan.tasks.reverse()  # the long and short runs now finish in another order
    rev = run_sweep(plan, executor="local", workers=2)
    assert [r.index for r in rev.rows] == [t.index for t in plan.tasks]
    in_order = sorted(rev.rows, key=lambda r: r.index)
    assert table_text(in_order, plan.points, rev.factor_names) == _text(serial)
