"""Replay bags through a twin and score it per signal: fit % as MATLAB ``compare`` defines it.

fit = 100 · (1 − ‖y − ŷ‖ / ‖y − ȳ‖) over the valid samples of the excited
axes' signals (x, p_c1, p_c2 for the cylinder; ω, p_m1 for the motor).

Two replays:

``closed``
    the recorded controller runs again, in closed loop with the twin, in the
    in-process runner (no supervisor: data after one of its events are not
    scored): an excitation bag's designs (metadata
    ``pneu.excite``) or a ``pneu run`` bag's controllers (``pneu.run``). The
    twin's sensors are noise- and offset-free (ŷ is the expected response).
``open``
    the twin on the recorded valve voltages (:mod:`pneu_control.sysid.shooting`),
    a pure simulation from the first sample (``horizon_s`` = ∞) or
    re-started from the measured state every ``horizon_s``.

Each pressure sensor's constant offset (the Huba 511's ±0.5 % FS; the twin
draws it per seed, so every bag has its own) is removed as the mean residual
before the fit is computed, and reported.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from pneu_msgs_py.params.core import with_updates

from pneu_control.sysid import shooting
from pneu_control.sysid.record import AXIS_SIGNALS, Record

__all__ = ["BagValidation", "fit_percent", "validate_record"]

PRESSURES = ("p_c1", "p_c2", "p_m1")
_UNITS = {"x": ("mm", 1e3), "p_c1": ("kPa", 1e-3), "p_c2": ("kPa", 1e-3), "p_m1": ("kPa", 1e-3), "omega": ("rpm", 60.0 / (2 * math.pi))}  # fmt: skip


def fit_percent(y: np.ndarray, yhat: np.ndarray) -> float:
    """100 (1 − ‖y − ŷ‖/‖y − ȳ‖) (NRMSE fit, MATLAB ``compare``)."""
    den = float(np.linalg.norm(y - np.mean(y)))
    if den == 0.0:
        return math.nan
    return 100.0 * (1.0 - float(np.linalg.norm(y - yhat)) / den)


@dataclass
class BagValidation:
    """The validation of one bag: the fit % per signal in ``mode``, the sensor offsets, and the
    traces behind them."""

    bag: str
    mode: str
    fits: dict[str, float]  # signal -> fit %
    offsets: dict[str, float] = field(default_factory=dict)  # Pa
    held_out: bool = True
    figure: str = ""
    t: np.ndarray | None = None
    y: dict[str, np.ndarray] = field(default_factory=dict)
    yhat: dict[str, np.ndarray] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The validation as plain data (the traces left out)."""
        return {
            "bag": self.bag,
            "mode": self.mode,
            "fit_percent": self.fits,
            "offsets_pa": self.offsets,
            "held_out": self.held_out,
            "figure": self.figure,
        }


def quiet_twin(plant):
    """The twin with noise-free, offset-free sensors (the expected response)."""
    return with_updates(
        plant,
        {
            "sensors.pressure.sigma_v": 0.0,
            "sensors.pressure.accuracy_fs": 0.0,
            "sensors.laser.sigma_m": 0.0,
        },
    )


def _recorded_controllers(rec: Record) -> dict[str, Any] | None:
    """The controllers a bag ran: its excitation designs, or a pneu run's controller params."""
    if rec.designs:
        return dict(rec.designs)
    from pneu_msgs_py.params.core import ParamError, from_dict

    from pneu_control.controller.params import AxisControllerParams

    try:
        return {
            a: from_dict(AxisControllerParams, c, strict=False) for a, c in rec.controllers.items()
        }
    except (ParamError, TypeError, ValueError):
        return None


def _closed(rec: Record, plant, axes: tuple[str, ...]) -> dict[str, np.ndarray] | None:
    from pneu_control.experiment.runner import RunSpec, run

    ctrls = _recorded_controllers(rec)
    if not ctrls or not set(axes) <= set(ctrls):
        return None
    x0 = float(rec.y["x"][0]) if math.isfinite(rec.y["x"][0]) else 0.0
    spec = RunSpec(
        axes=tuple(a for a in ("linear", "rotary") if a in ctrls),
        controllers=ctrls,
        plant=quiet_twin(plant),
        duration_s=rec.n * rec.period_s,
        seed=0,
        x0=max(-0.07, min(0.07, x0)),
        safety=None,  # noise-free sensors would trip the frozen-value rule; the recorded
        # data after any supervisor event are not scored anyway
    )
    res = run(spec)
    n = min(rec.n, len(res.t))
    return {k: v[:n] for k, v in res.samples.items()}


def validate_record(
    rec: Record,
    plant,
    *,
    mode: str = "open",
    horizon_s: float = math.inf,
    held_out: bool = True,
) -> BagValidation:
    """Replay ``rec`` through ``plant`` and score each excited axis's signals."""
    axes = tuple(a for a in ("linear", "rotary") if a in rec.designs or a in rec.commanded)
    if mode not in ("auto", "open", "closed"):
        raise ValueError(f"mode: {mode!r} refused; allowed: auto, open, closed")
    sim = None
    used = mode
    if mode in ("auto", "closed"):
        sim = _closed(rec, plant, axes)
        used = "closed"
        if sim is None and mode == "closed":
            raise ValueError(f"{rec.path}: no recorded controller to replay in closed loop")
    if sim is None:
        used = "open" if math.isinf(horizon_s) else f"open, restarted every {horizon_s:g} s"
        sim = {}
        mask_idx = {}
        for axis in axes:
            seg = shooting.segments_of(rec, axis, horizon_s)
            s = shooting.simulate(plant, rec, seg, {}, axis)
            for name in AXIS_SIGNALS[axis]:
                full = np.full(rec.n, math.nan)
                full[seg.index] = s[name]
                sim[name] = full
                mask_idx[name] = seg.index
    fits, offsets, ys, yh = {}, {}, {}, {}
    n = min(rec.n, *(len(v) for v in sim.values()))
    for axis in axes:
        ok = rec.valid[axis][:n]
        for name in AXIS_SIGNALS[axis]:
            y = rec.y[name][:n]
            yhat = np.asarray(sim[name][:n], dtype=float)
            m = ok & np.isfinite(y) & np.isfinite(yhat)
            if m.sum() < 10:
                continue
            if name in PRESSURES:
                off = float(np.mean(y[m] - yhat[m]))
                offsets[name] = off
                yhat = yhat + off
            fits[name] = fit_percent(y[m], yhat[m])
            ys[name], yh[name] = np.where(m, y, np.nan), np.where(m, yhat, np.nan)
    return BagValidation(rec.path, used, fits, offsets, held_out, t=rec.t[:n], y=ys, yhat=yh)


def plot_validation(v: BagValidation, out_png: str | Path) -> Path:
    """Overlay figure: one panel per signal, measured and twin."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(v.y)
    fig, axs = plt.subplots(
        len(names), 1, figsize=(11, 2.2 * len(names)), sharex=True, squeeze=False
    )
    for ax, name in zip(axs[:, 0], names):
        unit, k = _UNITS[name]
        ax.plot(v.t, v.y[name] * k, lw=0.6, label="measured")
        ax.plot(v.t, v.yhat[name] * k, lw=0.8, label="twin")
        ax.set_ylabel(f"{name} [{unit}]")
        ax.set_title(f"{name}: fit {v.fits[name]:.1f} %", fontsize=9, loc="left")
    axs[0, 0].legend(loc="upper right", fontsize=8)
    axs[-1, 0].set_xlabel("t [s]")
    tag = "held out" if v.held_out else "used by identify"
    fig.suptitle(f"{Path(v.bag).parent.name}/{Path(v.bag).name} ({v.mode}, {tag})", fontsize=10)
    fig.tight_layout()
    out_png = Path(out_png)
    fig.savefig(out_png, dpi=90, format="png")
    plt.close(fig)
    return out_png


def write_report(results: list[BagValidation], out_json: str | Path) -> None:
    """validate.json: the validations as a JSON list."""
    Path(out_json).write_text(
        json.dumps([replace(r).to_dict() for r in results], indent=2, sort_keys=True) + "\n"
    )
