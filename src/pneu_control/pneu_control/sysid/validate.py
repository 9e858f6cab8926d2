"""Replay bags through a twin and score it per signal: fit % as MATLAB ``compare`` defines it.

fit = 100 · (1 − ‖y − ŷ‖ / ‖y − ȳ‖) over the valid samples of each axis's
signals (x, p_c1, p_c2 for the cylinder; ω, p_m1 for the motor).

Every axis of the rig gets a result: its fits, or one line saying why not
(not in the bag, not excited, no valid stretch of data).

The measure (default, ``open``): the twin on the recorded valve voltages,
re-started from the measured state (:mod:`pneu_control.sysid.shooting`)
every h of :data:`HORIZONS_S` -- multi-step prediction at several horizons
(Ljung, *System Identification*, 2nd ed., sec. 16.6) -- and, h = ∞, a pure
simulation from the first sample of each stretch of valid data (MATLAB
``compare``'s default). The headline (``horizon_s``, default
:data:`HORIZON_S` = 1 s, what ``--min-fit`` judges and the figures show)
is the horizon a user of the twin needs: the time scale over which a
controller tuned on the twin relies on its prediction (the excitation's
pulses, a smooth step, half a period of the 0.25-0.5 Hz sines) and the
identification's own segment length on the cylinder. A pure simulation of
the cylinder, an integrator, scores the drift of its position over the whole
bag -- any velocity bias, which the position loop removes -- more than the
dynamics; a short horizon flatters any twin (it starts on the measurement).
So all of them are reported, the 1 s one judged.

Each pressure sensor's constant offset (the Huba 511's ±0.5 % FS; the twin
draws it per seed, so every bag has its own) is fitted once per bag and axis
by least squares on the pressures of the longest finite horizon's replay
(there the starting states are forgotten; a short replay starts on the
offset reading and hardly sees it), within ±7.5 kPa (identify's bound: an
offset cannot absorb what the twin gets wrong), and used at every horizon:
taken off the starting states, added to the twin's readings -- a sensor
property, not the twin's.

``closed`` / ``auto`` add the recorded controller run again in closed loop
with the twin, in the in-process runner (no supervisor: data after one of
its events are not scored): an excitation bag's designs (metadata
``pneu.excite``) or a ``pneu run`` bag's controllers (``pneu.run``); its
sensors are noise- and offset-free (ŷ is the expected response), the
offsets removed as the mean residual. ``closed``: that is the headline
(refused without a recorded controller); ``auto``: where the bag has one.

The residuals at the headline horizon are diagnosed
(:mod:`pneu_control.sysid.diagnostics`): whiteness, bias by operating
region, per segment, and the structural-mismatch warning.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pneu_msgs_py.params.core import with_updates

from pneu_control.sysid import diagnostics, shooting
from pneu_control.sysid.fit import OFFSET_BOUND_PA
from pneu_control.sysid.record import AXIS_SIGNALS, Record

__all__ = [
    "AxisValidation",
    "BagValidation",
    "HORIZONS_S",
    "HORIZON_S",
    "CLOSED",
    "fit_percent",
    "horizon_key",
    "horizon_label",
    "validate_record",
]

AXES = ("linear", "rotary")
HORIZONS_S = (0.2, 1.0, 5.0, math.inf)
HORIZON_S = 1.0
PRESSURES = ("p_c1", "p_c2", "p_m1")
PRESSURE_OF = {"linear": ("p_c1", "p_c2"), "rotary": ("p_m1",)}
_MIN_SAMPLES = 10
_OFFSET_STEP_PA = 1e3  # finite-difference step of the offsets' least squares
_OFFSET_ITERATIONS = 8
_OFFSET_TOL_PA = 10.0  # converged: a step below a tenth of the Huba's noise σ (~0.2 kPa)
_UNITS = {"x": ("mm", 1e3), "p_c1": ("kPa", 1e-3), "p_c2": ("kPa", 1e-3), "p_m1": ("kPa", 1e-3), "omega": ("rpm", 60.0 / (2 * math.pi))}  # fmt: skip


def fit_percent(y: np.ndarray, yhat: np.ndarray) -> float:
    """100 (1 − ‖y − ŷ‖/‖y − ȳ‖) (NRMSE fit, MATLAB ``compare``)."""
    den = float(np.linalg.norm(y - np.mean(y)))
    if den == 0.0:
        return math.nan
    return 100.0 * (1.0 - float(np.linalg.norm(y - yhat)) / den)


CLOSED = "closed"  # the key of the closed-loop replay's fits


def horizon_key(h: float) -> str:
    """The key of horizon ``h`` s in the results: ``1``, ``0.2``, ``inf``."""
    return "inf" if math.isinf(h) else f"{h:g}"


def horizon_label(key: str) -> str:
    """``1 s``, ``whole stretches`` (inf), ``closed loop``."""
    return {"inf": "whole stretches", CLOSED: "closed loop"}.get(key, f"{key} s")


@dataclass
class AxisValidation:
    """One axis of one bag: why it was not validated (``reason``), or its fits per horizon
    (:func:`horizon_key`, or :data:`CLOSED`), the offsets, the traces of the figure and the
    diagnostics."""

    axis: str
    reason: str = ""
    fits: dict[str, dict[str, float]] = field(default_factory=dict)
    offsets: dict[str, dict[str, float]] = field(default_factory=dict)  # Pa
    notes: list[str] = field(default_factory=list)
    diagnostics: diagnostics.AxisDiagnostics | None = None
    figure: str = ""
    t: np.ndarray | None = None
    y: dict[str, np.ndarray] = field(default_factory=dict)
    yhat: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)  # horizon -> traces

    @property
    def validated(self) -> bool:
        """Has this axis a fit at any horizon?"""
        return not self.reason

    def to_dict(self) -> dict[str, Any]:
        """The axis's validation as plain data (the traces left out; horizons by name)."""
        return {
            "validated": self.validated,
            "reason": self.reason,
            "fit_percent": self.fits,
            "offsets_pa": self.offsets,
            "notes": self.notes,
            "figure": self.figure,
            "diagnostics": None if self.diagnostics is None else self.diagnostics.to_dict(),
        }


@dataclass
class BagValidation:
    """The validation of one bag: per axis (:class:`AxisValidation`), the headline (a horizon
    key or :data:`CLOSED`) and whether identify used the bag."""

    bag: str
    mode: str
    headline: str
    axes: dict[str, AxisValidation]
    held_out: bool = True

    @property
    def fits(self) -> dict[str, float]:
        """Signal -> fit % at the headline, over every validated axis."""
        out: dict[str, float] = {}
        for a in self.axes.values():
            out.update(a.fits.get(self.headline, {}))
        return out

    @property
    def offsets(self) -> dict[str, float]:
        """Pressure signal -> offset (Pa) at the headline."""
        out: dict[str, float] = {}
        for a in self.axes.values():
            out.update(a.offsets.get(self.headline, {}))
        return out

    @property
    def horizons(self) -> list[str]:
        """The horizon keys with a fit on any axis, shortest first (closed loop last)."""
        hs = {h for a in self.axes.values() for h in a.fits}
        return sorted(hs, key=lambda h: math.inf if h == CLOSED else float(h))

    @property
    def warnings(self) -> list[str]:
        """The structural-mismatch warnings of the axes."""
        return [a.diagnostics.warning for a in self.axes.values() if a.diagnostics and a.diagnostics.warning]  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        """The validation as plain data (the traces left out)."""
        return {
            "bag": self.bag,
            "mode": self.mode,
            "headline": self.headline,
            "fit_percent": self.fits,
            "offsets_pa": self.offsets,
            "held_out": self.held_out,
            "structural_mismatch": self.warnings,
            "axes": {a: v.to_dict() for a, v in self.axes.items()},
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
        axes=tuple(a for a in AXES if a in ctrls),
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
    out = {}
    for k, v in res.samples.items():
        full = np.full(rec.n, math.nan)
        full[:n] = v[:n]
        out[k] = full
    return out


def _not_validated(rec: Record, axis: str) -> str:
    """Why ``axis`` cannot be validated on ``rec`` at all ("" if it can)."""
    if axis not in rec.designs and axis not in rec.commanded:
        return "not in this bag (no valve commands recorded)"
    u = rec.u[axis][rec.valid[axis]]
    if axis not in rec.designs and (not len(u) or np.ptp(u) <= 0.05):
        return "not excited in this bag (valve voltage constant)"
    if not rec.valid[axis].any():
        return "no valid data (" + "; ".join(_axis_notes(rec, axis)) + ")"
    return ""


def _axis_notes(rec: Record, axis: str) -> list[str]:
    """The record's notes about ``axis`` (a supervisor event, lost commands) or all samples."""
    return [n for n in rec.notes if n.startswith(f"{axis}:") or "samples missing" in n]


def _offsets(rec: Record, plant, axis: str, seg: shooting.Segments) -> dict[str, float]:
    """The pressure sensors' offsets of ``axis`` that make the replay on ``seg`` fit the
    pressures best (least squares, Gauss-Newton with steps that lower the sum of squares),
    within the bound."""
    names = PRESSURE_OF[axis]
    idx = seg.index
    y = np.concatenate([rec.y[n][idx] for n in names])
    ok = np.isfinite(y)
    off = dict.fromkeys(names, 0.0)

    def stacked(o):
        yq = np.concatenate([v for k, v in shooting.simulate(plant, rec, seg, o, axis).items() if k in names])  # fmt: skip
        return yq, float(np.sum(((y - yq)[ok & np.isfinite(yq)]) ** 2))

    yh, sse = stacked(off)
    for _ in range(_OFFSET_ITERATIONS):
        J = np.empty((len(y), len(names)))
        for j, n in enumerate(names):
            J[:, j] = (stacked({**off, n: off[n] + _OFFSET_STEP_PA})[0] - yh) / _OFFSET_STEP_PA
        good = ok & np.all(np.isfinite(J), axis=1) & np.isfinite(yh)
        step = np.linalg.lstsq(J[good], (y - yh)[good], rcond=None)[0]
        for scale in (1.0, 0.5, 0.25):
            trial = {
                n: float(np.clip(off[n] + scale * d, -OFFSET_BOUND_PA, OFFSET_BOUND_PA))
                for n, d in zip(names, step)
            }
            got = stacked(trial)
            if got[1] < sse:
                break
        if got[1] >= sse:
            break
        moved = max(abs(trial[n] - off[n]) for n in names)
        off, (yh, sse) = trial, got
        if moved < _OFFSET_TOL_PA:
            break
    return off


def _score(rec: Record, axis: str, idx: np.ndarray, sim: dict[str, np.ndarray]):
    """Fit % per signal of ``sim`` (at sample indices ``idx``) and the full-length traces."""
    fits, ys, yh = {}, {}, {}
    ok = rec.valid[axis][idx]
    for name in AXIS_SIGNALS[axis]:
        y, yhat = rec.y[name][idx], np.asarray(sim[name], dtype=float)
        m = ok & np.isfinite(y) & np.isfinite(yhat)
        if m.sum() < _MIN_SAMPLES:
            continue
        fits[name] = fit_percent(y[m], yhat[m])
        full = np.full(rec.n, math.nan)
        full[idx[m]] = yhat[m]
        yh[name] = full
        yfull = np.full(rec.n, math.nan)
        yfull[idx[m]] = y[m]
        ys[name] = yfull
    return fits, ys, yh


def _validate_axis(
    rec: Record, plant, axis: str, horizons: tuple[float, ...], headline: float, noise
) -> AxisValidation:
    av = AxisValidation(axis, reason=_not_validated(rec, axis), notes=_axis_notes(rec, axis))
    if av.reason:
        return av
    av.t = rec.t
    segs = {h: shooting.segments_of(rec, axis, h) for h in horizons}
    segs = {h: s for h, s in segs.items() if int(s.lengths.sum()) >= _MIN_SAMPLES}
    pieces = {}
    if segs:
        # the offsets once, on the longest finite horizon's replay: there the starts are
        # forgotten and an offset shows whole (a short replay starts on the offset reading)
        h_off = max(segs, key=lambda h: (math.isfinite(h), h if math.isfinite(h) else 0.0))
        off = _offsets(rec, plant, axis, segs[h_off])
    for h, seg in segs.items():
        sim = shooting.simulate(plant, rec, seg, off, axis)
        fits, ys, yh = _score(rec, axis, seg.index, sim)
        if not fits:
            continue
        key = horizon_key(h)
        av.fits[key], av.offsets[key], av.yhat[key] = fits, off, yh
        if not av.y or h == headline:
            av.y = ys
        pieces[h] = diagnostics.Piece(rec, seg, sim)
    if not av.fits:
        # each note's head only (its detail is in the notes): one line for the refusal
        heads = (n.removeprefix(f"{axis}: ").split(": ")[0] for n in av.notes)
        why = "; ".join(heads) or "too few valid samples"
        av.reason = f"no valid stretch of {horizon_label(horizon_key(min(horizons)))}: {why}"
        return av
    # the diagnostics judge the headline's residuals (a pure simulation, one segment per
    # stretch, gives the sign-flip test nothing to flip: then the longest finite horizon's)
    finite = [h for h in pieces if math.isfinite(h)]
    if finite:
        h_d = headline if headline in finite else max(finite)
        av.diagnostics = diagnostics.diagnose(axis, [pieces[h_d]], noise)
    return av


def validate_record(
    rec: Record,
    plant,
    *,
    mode: str = "open",
    horizon_s: float = HORIZON_S,
    held_out: bool = True,
    horizons: tuple[float, ...] = HORIZONS_S,
) -> BagValidation:
    """Replay ``rec`` through ``plant``: every axis at ``horizons`` (and ``horizon_s``, the
    headline), plus the closed-loop replay in mode ``closed`` / ``auto`` (see the module
    docstring)."""
    if mode not in ("auto", "open", "closed"):
        raise ValueError(f"mode: {mode!r} refused; allowed: auto, open, closed")
    from pneu_control.sysid.identify import estimate_noise

    hs = tuple(sorted(set(horizons) | {horizon_s}))
    present = tuple(a for a in AXES if not _not_validated(rec, a))
    noise = {k: v.sigma for k, v in estimate_noise([rec], present).items()}
    axes = {a: _validate_axis(rec, plant, a, hs, horizon_s, noise) for a in AXES}
    headline = horizon_key(horizon_s)
    used = "open" if math.isinf(horizon_s) else f"open, restarted every {horizon_s:g} s"
    if mode in ("auto", "closed"):
        sim = _closed(rec, plant, tuple(a for a in AXES if axes[a].validated))
        if sim is None and mode == "closed":
            raise ValueError(f"{rec.path}: no recorded controller to replay in closed loop")
        if sim is not None:
            headline, used = CLOSED, "closed"
            for av in axes.values():
                if av.validated:
                    _closed_fits(rec, av, sim)
    return BagValidation(rec.path, used, headline, axes, held_out)


def _closed_fits(rec: Record, av: AxisValidation, sim: dict[str, np.ndarray]) -> None:
    """The closed-loop replay's fits of ``av``'s axis, each pressure's mean residual (its
    sensor's offset) taken off."""
    idx = np.arange(rec.n)
    fits, _ys, yh = _score(rec, av.axis, idx, sim)
    offs = {}
    for name in PRESSURE_OF[av.axis]:
        if name in yh:
            m = np.isfinite(yh[name]) & np.isfinite(rec.y[name])
            offs[name] = float(np.mean(rec.y[name][m] - yh[name][m]))
            yh[name] = yh[name] + offs[name]
            fits[name] = fit_percent(rec.y[name][m], yh[name][m])
    av.fits[CLOSED], av.offsets[CLOSED], av.yhat[CLOSED] = fits, offs, yh


def plot_validation(v: BagValidation, axis: str, out_png: str | Path) -> Path:
    """Overlay figure of one axis: one panel per signal, measured, the twin at the headline and
    in a pure simulation; a text panel with the reason when the axis was not validated."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    av = v.axes[axis]
    names = [n for n in AXIS_SIGNALS[axis] if n in av.y] if av.validated else []
    rows = max(len(names), 1)
    fig, axs = plt.subplots(rows, 1, figsize=(11, 2.2 * rows), sharex=True, squeeze=False)
    tag = "held out" if v.held_out else "used by identify"
    title = f"{Path(v.bag).parent.name}/{Path(v.bag).name}: {axis} ({tag})"
    if not names:
        axs[0, 0].text(0.5, 0.5, f"{axis}: not validated: {av.reason}", ha="center", wrap=True)
        axs[0, 0].set_axis_off()
    shown = [h for h in dict.fromkeys((v.headline, "inf")) if h in av.yhat]
    for ax, name in zip(axs[:, 0], names):
        unit, k = _UNITS[name]
        ax.plot(av.t, av.y[name] * k, lw=0.6, color="k", label="measured")
        for j, h in enumerate(shown):
            if name in av.yhat[h]:
                ax.plot(av.t, av.yhat[h][name] * k, lw=0.8 - 0.2 * j, ls="-" if j == 0 else "--",
                        label=f"twin, {horizon_label(h)}")  # fmt: skip
        fits = ", ".join(
            f"{f[name]:.1f} % ({horizon_label(h)})" for h, f in av.fits.items() if name in f
        )
        ax.set_ylabel(f"{name} [{unit}]")
        ax.set_title(f"{name}: fit {fits}", fontsize=8, loc="left")
    if names:
        axs[0, 0].legend(loc="upper right", fontsize=7)
    axs[-1, 0].set_xlabel("t [s]")
    if av.diagnostics is not None and av.diagnostics.warning:
        title += "\n" + av.diagnostics.warning.split(" -- ")[0]
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    out_png = Path(out_png)
    fig.savefig(out_png, dpi=90, format="png")
    plt.close(fig)
    return out_png


def write_report(results: list[BagValidation], out_json: str | Path) -> None:
    """validate.json: the validations as a JSON list."""
    Path(out_json).write_text(
        json.dumps([r.to_dict() for r in results], indent=2, sort_keys=True, default=float) + "\n"
    )
