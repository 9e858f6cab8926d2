"""ESO-SMC+ on the physics twin against the re-tuned ESO-SMC; robustness; bumpless switching.

Short runs (a few simulated seconds). ESO-SMC runs with the re-tuned set
(config/controllers_retuned.yaml); ESO-SMC+ with its design-rule gains in
config/controllers.yaml (b0 = 1.5 x identified; see the module docstring of
pneu_control.algorithms.eso_smc_plus).
"""

import numpy as np
import pytest
from pneu_control.controller.axis import AxisController
from pneu_control.controller.params import load_controller_params
from pneu_control.experiment import session
from pneu_control.experiment.runner import run
from pneu_msgs_py.contract.samples import NEUTRAL_V
from pneu_msgs_py.params.core import with_updates
from pneu_msgs_py.params.paths import config_file
from pneu_sim.physics.plant import Plant
from pneu_sim.physics.plant_file import load_plant

RETUNED = config_file("controllers_retuned.yaml")
DEFAULTS = config_file("controllers.yaml")
SINE = "sine:amplitude=20,frequency_hz=0.5,offset=0"  # window opens after 2 periods (4 s)
SPEED = "constant:value=800"


def _metrics(axis, controller, reference, duration, seed=0, plant=None):
    cf = DEFAULTS if controller == "eso_smc_plus" else RETUNED
    spec = session.build_spec(
        axes=(axis,),
        controller=controller,
        reference=reference,
        duration_s=duration,
        seed=seed,
        controllers_file=cf,
        plant=plant,
    )
    return run(spec).metrics[axis]


def _corner(mass=1.0, supply=1.0):
    p = load_plant(None)
    return with_updates(
        p,
        {
            "linear.M": p.linear.M * mass,
            "supply.p_s_linear": p.supply.p_s_linear * supply,
            "supply.p_s_rotary": p.supply.p_s_rotary * supply,
        },
    )


@pytest.mark.parametrize("supply", [1.0, 0.7, 1.3])
def test_angle_observer_beats_eso_smc_at_800_rpm(supply):
    # the rotary twin has no random part (encoder counts, deterministic ripple): one seed
    plant = _corner(supply=supply)
    plus = _metrics("rotary", "eso_smc_plus", SPEED, 4.0, plant=plant)
    base = _metrics("rotary", "eso_smc", SPEED, 4.0, plant=plant)
    assert plus.e_max < base.e_max
    assert plus.rmse < base.rmse


@pytest.mark.parametrize(("mass", "supply"), [(0.7, 1.0), (1.3, 1.0), (1.0, 0.7), (1.0, 1.3)])
def test_stable_with_mass_and_supply_off_by_30_percent(mass, supply):
    plant = _corner(mass, supply)
    lin = _metrics("linear", "eso_smc_plus", SINE, 6.0, plant=plant)
    assert lin.rmse < 0.8  # mm (nominal 0.41 on this 0.5 Hz sine; ESO-SMC 0.37)
    assert lin.e_max < 2.5
    rot = _metrics("rotary", "eso_smc_plus", SPEED, 4.0, plant=plant)
    assert rot.e_max < 1.5  # rpm, per-revolution mean speed (nominal 0.6)


@pytest.mark.parametrize("axis", ["linear", "rotary"])
def test_switching_to_and_from_eso_smc_plus_is_bumpless(axis):
    ref = {"reference.kind": "constant", "reference.value": 800.0}
    if axis == "linear":
        ref = {"reference.kind": "sine", "reference.amplitude": 20.0, "reference.frequency_hz": 0.5}
    base = with_updates(load_controller_params(axis, RETUNED), {**ref, "algorithm": "eso_smc"})
    plus = with_updates(
        load_controller_params(axis, DEFAULTS), {**ref, "algorithm": "eso_smc_plus"}
    )
    ctrl = AxisController(axis, base)
    plant = Plant(load_plant(None), seed=0)
    s = plant.reset()
    u_hold = NEUTRAL_V
    switches = {1500: plus, 3000: base, 4500: plus}
    u = np.empty(6000)
    err = np.empty(6000)
    for k in range(6000):
        if k in switches:
            ctrl.set_params(switches[k])
        u[k] = ctrl.update(s)
        err[k] = ctrl.state.error
        s = plant.step(*((u_hold, NEUTRAL_V) if axis == "linear" else (NEUTRAL_V, u_hold)))
        u_hold = u[k]
    du = np.abs(np.diff(u))
    typical = np.percentile(du[500:1490], 99)
    for k in switches:
        # the command never jumps at a switch: the step there is an ordinary one
        assert du[k - 1] <= max(2.0 * typical, 1e-3)
        assert ctrl.algorithm in ("eso_smc", "eso_smc_plus")
    if axis == "linear":
        assert np.max(np.abs(err[1000:])) * 1e3 < 2.5  # mm, raw (noisy) error
    else:  # speed over 75 ms (one revolution): quantisation and vane ripple averaged out
        w = np.convolve(err[1400:], np.ones(75) / 75.0, mode="valid") * 60.0 / (2.0 * np.pi)
        # the handover settles within ≈ 0.5 s with a ≈ 17 rpm per-revolution excursion (λ_R = 10)
        assert np.max(np.abs(w)) < 20.0
    assert ctrl.algorithm == "eso_smc_plus"


@pytest.mark.parametrize("speed", [600.0, 800.0, 1100.0])
@pytest.mark.parametrize("mass,supply", [(1.0, 1.0), (1.3, 0.7), (0.7, 1.3)])
def test_angle_observer_no_limit_cycle_across_speeds_and_corners(speed, mass, supply):
    """b0 = 1.5 x identified (gain margin): no limit cycle from 600 to 1100 rpm, at the
    ±30 % inertia/supply corners (robustness.scaled_plant scales J_m and the supplies)."""
    from dataclasses import replace

    from pneu_control.analysis.metrics import WindowSpec
    from pneu_control.experiment.robustness import scaled_plant

    spec = session.build_spec(
        axes=("rotary",),
        controller="eso_smc_plus",
        reference=f"constant:value={speed}",
        duration_s=4.0,
        controllers_file=DEFAULTS,
        plant=scaled_plant(load_plant(None), mass=mass, supply=supply),
    )
    window = WindowSpec("fixed", t_start_s=2.5, average_s=60.0 / speed)
    m = run(replace(spec, windows={"rotary": window})).metrics["rotary"]
    assert m.e_max < 2.0  # rpm per revolution; a limit cycle is 10–70 rpm


def test_beats_eso_smc_on_the_paper_sine_over_seeds():
    """Sine 20 mm, 0.25 Hz, window 8–20 s: mean e_max and mean RMSE over seeds 0–2 below
    ESO-SMC's (laser noise makes one run's e_max a poor statistic: compare means)."""
    from dataclasses import replace

    from pneu_control.experiment.catalog import experiment_by_id

    exp = experiment_by_id("sine_20mm_0p25hz")

    def metrics(controller, seed):
        spec = session.build_spec(
            axes=("linear",),
            controller=controller,
            reference=dict(exp.reference),
            duration_s=exp.duration_s,
            seed=seed,
            controllers_file=DEFAULTS if controller == "eso_smc_plus" else RETUNED,
        )
        return run(replace(spec, windows={"linear": exp.window})).metrics["linear"]

    plus = [metrics("eso_smc_plus", s) for s in range(3)]
    base = [metrics("eso_smc", s) for s in range(3)]
    assert np.mean([m.e_max for m in plus]) < np.mean([m.e_max for m in base])
    assert np.mean([m.rmse for m in plus]) < 0.8 * np.mean([m.rmse for m in base])
