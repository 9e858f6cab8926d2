"""Tuning that transfers (CI-fast): gains tuned on the identified twin, run on the true one.

The true plant has the motor inertia ×1.6; the identified one comes from a
quick rotary excitation of it. ``pneu tune``'s method (b0 from the step
response, the PID grid -- every 4th point here, nominal plant only, for
time) runs on both; both gain sets then run the paper's 800 rpm experiment
on the true plant. The identified twin's gains must come within 20 % of the
true twin's e_max and RMSE. tools/sysid_study.py measures every controller.
"""

from __future__ import annotations

import pytest
from pneu_control.sysid import study
from pneu_control.sysid.excite import excitation_spec, run_excitation
from pneu_control.sysid.identify import identify
from pneu_control.sysid.record import load_record
from pneu_control.sysid.transfer import TRANSFER_TOLERANCE, transfer
from pneu_sim.physics.plant_file import load_plant


@pytest.fixture(scope="module")
def plants(tmp_path_factory):
    out = tmp_path_factory.mktemp("transfer")
    base = load_plant()
    truth = study.perturbed_plant(base, "J_m x1.6")
    run_excitation(
        excitation_spec(("rotary",), truth, seed=0, level="quick"),
        out,
        progress=False,
        hide_plant=True,
    )
    ident = identify([load_record(out / "run.mcap")], base, axes=("rotary",), log=lambda m: None)
    return base, truth, ident.plant


def test_rotary_pid_gains_transfer(plants):
    _base, truth, identified = plants
    assert abs(identified.rotary.J_m / truth.rotary.J_m - 1.0) < 0.1
    rows = transfer(truth, identified, ("rotary",), ("pid",), stride=4, corners=False, experiments=("speed_800rpm",), log=lambda m: None)  # fmt: skip
    assert [(r.algorithm, r.experiment) for r in rows] == [("pid", "speed_800rpm")]
    r = rows[0]
    assert r.gap_e_max <= TRANSFER_TOLERANCE, r.markdown()
    assert r.gap_rmse <= TRANSFER_TOLERANCE, r.markdown()
