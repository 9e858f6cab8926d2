"""Output-error fit of the twin to bags: least squares over the uncertain parameters, with statistics.

Per axis (the cylinder and the motor share only the polytropic index, fitted
on the cylinder; the motor sees it only as n/V: :func:`in_polytropic_index`), the
residual is the difference between each recorded
signal and the twin replayed on the recorded voltages
(:mod:`pneu_control.sysid.shooting`), signal by signal divided by the
signal's spread, so the cost is the sum over signals of (1 − fit)² with fit
as ``pneu validate`` reports it. ``scipy.optimize.least_squares`` (trust
region reflective, within the physical bounds of
:mod:`pneu_control.sysid.model`) minimises it; the Jacobian is by finite
differences of relative size ``diff_step`` (its columns on the replay's worker threads)
every ``jacobian_every``-th step, Broyden's secant update between
(:meth:`Problem._least_squares`).

Besides the plant parameters each bag gets its pressure sensors' offsets
(nuisance parameters: the Huba 511's ±0.5 % FS), reported but not written
to the plant file.

Statistics at the optimum: the covariance of the estimate is cluster-robust
over the replayed segments (the sandwich (JᵀJ)⁻¹ (Σ_g J_gᵀ r_g r_gᵀ J_g)
(JᵀJ)⁻¹: within a segment the residuals are anything but independent, one
start error runs through the whole replay), and ``identify`` widens it by
parametric-bootstrap draws (:mod:`pneu_control.sysid.replicate`: measured
over noise seeds on a plant of the model's own family, the estimator scatters
5-15 times more than any linearised covariance says -- the cost is rough
where the motor creeps and sticks); the correlation matrix of the estimates,
and every pair with |ρ| > 0.9 is reported: the two trade against each other
(not separately identifiable from these bags). The linearised covariance of
Ljung's *System Identification* §9.3 (s² (JᵀJ)⁻¹, inflated by the residuals'
integrated autocorrelation time) is kept as ``sigma_iid`` for comparison.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from pneu_msgs_py.params.core import with_updates
from pneu_sim.physics import workers

from pneu_control.sysid import model, shooting, starts
from pneu_control.sysid.record import AXIS_SIGNALS, Record

__all__ = [
    "AxisFit",
    "FitOptions",
    "Problem",
    "fit_axis",
    "in_polytropic_index",
    "refit",
    "with_replicate",
]

_OFFSET_WIDTH = 5e3  # Pa: z = 1 is one Huba accuracy band
# Huba 511: ±0.5 % FS = ±5 kPa; the bound allows 1.5x that, so an offset cannot
# absorb what the supply pressure or the flow curve should explain
OFFSET_BOUND_PA = 7.5e3
_PRESSURE_OF = {"linear": ("p_c1", "p_c2"), "rotary": ("p_m1",)}
CORRELATED = 0.9  # |ρ| above which two estimates trade against each other


@dataclass(frozen=True)
class FitOptions:
    """How the output-error fit runs: segment lengths, decimation, the least-squares steps and
    stops, the parameters fitted."""

    segment_s: dict[str, float] = field(default_factory=lambda: {"linear": 1.0, "rotary": 2.0})
    decimate: int = 4  # residual every 4th sample
    diff_step: float = 3e-3
    max_nfev: int = 40
    ftol: float = 1e-3  # stop when a step lowers the cost by less than 0.1 %
    xtol: float = 1e-4
    params: tuple[str, ...] | None = None  # names to fit (default: every parameter of the axis)
    short_segment_s: float = 0.2  # the flow-curve stage's smooth cost (see _scan_dead_band)
    short_every: int = 3  # ... on every 3rd short segment
    settle_segment_s: float = 0.5  # a solve's first pass: shorter segments (see _continued)
    settle_every: int = 2  # ... every 2nd of them
    curve: bool = True  # last stage: the valve's own curve (pneu_control.sysid.curve)
    jacobian_every: int = 3  # a Jacobian by differences every 3rd step, Broyden's between
    # substeps per period of the replays that only look for a basin (the scans, stage 2a, the
    # first pass of each continuation, the unexplained segments alone); every pass whose cost
    # is compared or reported replays at the plant's own (Problem(coarse=...))
    basin_n_sub: int | None = 5


@dataclass
class AxisFit:
    """The fit of one axis: the parameters' base and fitted values with 1 σ and correlations, the
    sensor offsets, the cost and effort."""

    axis: str
    names: list[str]
    units: list[str]
    base: list[float]
    value: list[float]
    sigma: list[float]  # 1 σ, in the parameter's unit
    corr: np.ndarray
    offsets: dict[str, dict[str, float]]  # record name -> signal -> Pa
    offsets_sigma: dict[str, dict[str, float]]
    cost_start: float
    cost: float
    nfev: int
    wall_s: float
    inflation: float
    n_residuals: int
    status: str
    plant: object = None  # the fitted PlantParams
    sigma_iid: list[float] = field(default_factory=list)  # 1 σ, white residuals inflated by τ
    n_clusters: int = 0  # replayed segments the sandwich σ rests on
    sigma_fit: list[float] = field(default_factory=list)  # 1 σ of the fit alone (the sandwich)
    replicate_shift: list[float] = field(default_factory=list)  # RMS d of the bootstrap draws
    unexplained: list[str] = field(default_factory=list)  # the per-segment check's lines
    q95: float = 1.96  # the 95 % quantile the intervals use (Student's t with the draws' dof)
    fit_params: tuple = ()  # the FitParams of ``names`` (model.FitParam)
    curve_support: object = None  # what the data inform of the valve's own curve (curve stage)
    about: object = None  # the PlantParams the coordinates are about (a curve's handles: its shape)

    def offset_start(self) -> dict[str, float]:
        """The sensor offsets as start values (``offset:<record>:<signal>`` -> Pa)."""
        return {f"offset:{r}:{k}": v for r, o in self.offsets.items() for k, v in o.items()}

    def start(self) -> dict[str, float]:
        """The fitted values and offsets as a start (:meth:`Problem.z_start`)."""
        return {**dict(zip(self.names, self.value)), **self.offset_start()}

    def ci95(self, i: int) -> float:
        """95 % half-width of parameter ``i`` (q95 σ), in its unit."""
        return self.q95 * self.sigma[i]

    def rel_ci95(self, i: int) -> float:
        """95 % half-width relative to the value (log parameters; a dead band: in V)."""
        v = self.value[i]
        return self.ci95(i) / abs(v) if v else math.inf

    def correlated_pairs(self, limit: float = CORRELATED) -> list[tuple[str, str, float]]:
        """Pairs of fitted parameters whose correlation exceeds ``limit`` in magnitude: (name, name,
        r)."""
        out = []
        n = len(self.names)
        for i in range(n):
            for j in range(i + 1, n):
                r = float(self.corr[i, j])
                if abs(r) > limit:
                    out.append((self.names[i], self.names[j], r))
        return out


def _autocorr_time(r: np.ndarray, max_lag: int = 200) -> float:
    """Integrated autocorrelation time 1 + 2 Σ ρ(k) (truncated at the first ρ ≤ 0)."""
    r = r - r.mean()
    v = float(np.dot(r, r))
    if v <= 0.0 or len(r) < 4:
        return 1.0
    tau = 1.0
    for k in range(1, min(max_lag, len(r) // 4)):
        rho = float(np.dot(r[:-k], r[k:])) / v
        if rho <= 0.0:
            break
        tau += 2.0 * rho
    return tau


STAGES = 5  # flow curve, every parameter, each once again (_staged_fit), the own curve


def fit_axis(
    axis: str,
    base,
    records: list[Record],
    options: FitOptions | None = None,
    log: Callable[[str], None] = print,
    stage: Callable[[], None] = lambda: None,
) -> AxisFit:
    """Fit ``axis``'s parameters of ``base`` (PlantParams) to ``records``: the staged fit in
    the catalogue curve's family (:func:`_staged_fit`); the per-segment check
    (:mod:`pneu_control.sysid.groups`): where some segments are not explained, the whole fit
    again from their own optimum, the lower cost kept; then, with ``options.curve``, the
    valve's own curve (:func:`_fit_own_curve`). What is still unexplained at the end goes
    into :attr:`AxisFit.unexplained`.

    ``stage()`` is called as each of the (at most :data:`STAGES`) stages begins.
    """
    from pneu_control.sysid import groups

    options = options or FitOptions()
    fit = _staged_fit(axis, base, records, options, log, stage)
    full = Problem(axis, base, records, replace(options, params=tuple(fit.names)))
    check = groups.check_segments(full, full.z_start(fit.start()))
    start = groups.refit_unexplained(axis, base, records, options, fit, check, log)
    if start is not None:
        log(f"  {axis}: global stage: every parameter again, from there")
        again = _continued(full, start, log)
        log(f"  {axis}: cost {again.cost:.5g} there, {fit.cost:.5g} before")
        if again.cost < fit.cost:
            fit = replace(again, cost_start=fit.cost_start)
            check = groups.check_segments(full, full.z_start(fit.start()))
    if options.curve and f"valve_{axis}.Q_n" in fit.names:
        stage()
        own = _fit_own_curve(axis, base, records, options, fit, log)
        if own is not None:
            fit, prob = own
            check = groups.check_segments(prob, prob.z_start(fit.start()))
    return replace(fit, unexplained=check.lines(axis))


def _fit_own_curve(axis, base, records, options, fit: AxisFit, log):
    """The last stage: the valve's own monotone curve per port (knots where the data are,
    :mod:`pneu_control.sysid.curve`) with every other parameter but the catalogue curve's
    scale and dead band, from the catalogue-family fit ``fit``: (the fit, its Problem), or
    None when it does not lower the cost.

    The catalogue family is a shift and a scale of one shape; a valve of another shape
    near the null makes the leakage and friction stand in for the difference there. The
    start is ``fit``'s curve itself (written on the chart's breakpoints), so this stage
    only ever moves away from it where the data say so.
    """
    from pneu_control.sysid import curve

    valve = f"valve_{axis}"
    estimate = None
    if axis == "linear":  # the chambers as flow meters: a direct measurement to start from
        from pneu_control.sysid.valve_flow import estimate_curve

        estimate = estimate_curve(fit.plant, records, fit.offsets)
    start_plant = curve.own_curve_plant(fit.plant, axis, estimate)
    knots, sup = curve.fit_params(axis, start_plant, records)
    drop = {f"{valve}.Q_n", f"{valve}.{model.DEAD_BAND}"}
    others = [n for n in fit.names if n not in drop]
    log(
        f"  {axis}: stage 3, the valve's own curve: {len(knots)} knots "
        f"({sup.text()}) with {len(others)} other parameters"
    )
    prob = Problem(
        axis,
        start_plant,
        records,
        replace(options, params=(*others, *(p.name for p in knots))),
        extra=knots,
    )
    dp = len(prob.params) - len(fit.names)

    def worth_solving(first: AxisFit) -> bool:
        return _pays_on_first_pass(prob, fit, records, first, dp, log)

    own = _continued(prob, fit.offset_start(), log, go_on=worth_solving)
    if own is None:
        return None
    # Kept only when the lower cost pays for the values added: Schwarz's criterion (BIC;
    # Schwarz, Ann. Statist. 6, 1978) on the effective sample, the residuals over their
    # autocorrelation time (the larger of the two fits'). A cost merely lower is what 30
    # knots find in noise and in what the catalogue family explains otherwise (the study's
    # breakaway plant: -11 %, and a mismatch warning held out).
    gain, price = _bic(fit.cost, own.cost, own.n_residuals, (fit.inflation, own.inflation), dp)
    m_eff = own.n_residuals / max(fit.inflation, own.inflation, 1.0)
    if not gain > price:
        log(
            f"  {axis}: own curve cost {own.cost:.5g} against {fit.cost:.5g}: "
            f"{gain:.0f} <= {price:.0f} (BIC, {m_eff:.0f} effective residuals, {dp} more "
            "values): the catalogue family kept"
        )
        return None
    log(
        f"  {axis}: own curve cost {own.cost:.5g} against {fit.cost:.5g}: {gain:.0f} > {price:.0f} (BIC)"
    )
    # the report's base column: the values identify started from, not this stage's start
    own.base = [
        own.base[i] if model.is_handle(n) else model.base_value(base, own.fit_params[i])
        for i, n in enumerate(own.names)
    ]
    own.cost_start = fit.cost_start
    own.nfev += fit.nfev
    own.wall_s += fit.wall_s
    own.curve_support = sup
    return own, prob


def _pays_on_first_pass(prob: Problem, fit: AxisFit, records, first: AxisFit, dp: int, log) -> bool:
    """The BIC of an own curve (``prob``, ``dp`` values more than the catalogue family's
    ``fit``) on its continuation's first pass ``first``, the gain scaled to the whole
    record: a curve that could not pay half its price there is not solved on the long
    segments."""
    axis, options = prob.axis, prob.options
    settle = _settle_options(options, axis)
    cat = Problem(axis, fit.about, records, replace(settle, params=tuple(fit.names)),
                  every=options.settle_every, coarse=True)  # fmt: skip
    cost = cat.cost(cat.z_start(fit.start()))
    taus = (fit.inflation, first.inflation)
    gain, _ = _bic(cost, first.cost, first.n_residuals, taus, dp)
    predicted = gain * len(prob.cluster) / first.n_residuals  # residuals of the record
    _, price = _bic(cost, first.cost, len(prob.cluster), taus, dp)
    if predicted > 0.5 * price:
        return True
    log(
        f"  {axis}: own curve on the first pass: cost {first.cost:.5g} against the "
        f"catalogue's {cost:.5g} there, a gain of {predicted:.0f} over the record "
        f"against a price of {price:.0f} (BIC): the catalogue family kept"
    )
    return False


def _bic(cost_before: float, cost_after: float, n: int, taus, dp: int) -> tuple[float, float]:
    """Schwarz's criterion for ``dp`` more values: (gain, price) on the effective sample, the
    ``n`` residuals over the larger of their autocorrelation times ``taus``; the values pay
    when gain > price."""
    m_eff = n / max(*taus, 1.0)
    gain = m_eff * math.log(cost_before / cost_after) if cost_after > 0 else math.inf
    return gain, math.log(m_eff) * dp


# The volumes first: with the catalogue's volume the first steps of a joint fit trade the
# flow scale and the supply against it and leave for a valley of leakages (issue 21's motor).
_VOLUMES = ("rotary.V_m1",)
_UNOBSERVABLE = ("rotary.V_m2",)  # no sensor on it: it only moves once everything else has


def _settling_groups(axis: str, names, mech) -> list[tuple[str, ...]]:
    """The groups stage 2a fits in turn, the mechanics pinned at their equation-error values:
    the volumes, then everything but the unobservable."""
    vol = tuple(n for n in names if n in _VOLUMES and n not in mech)
    rest = tuple(n for n in names if n not in mech and n not in _UNOBSERVABLE)
    return [g for g in (vol, rest) if g]


def _staged_fit(axis, base, records, options, log, stage) -> AxisFit:
    """Fit ``axis``'s parameters of ``base`` (PlantParams) to ``records`` with the valve's curve
    a shift and scale of the catalogue's.

    Stage 1: the valve's flow curve (scale and dead band: what sets the
    operating points, and what a start far off gets most wrong) by
    :func:`_scan_dead_band`; stage 2: every parameter by least squares from
    there -- otherwise the friction, supply and exhaust parameters absorb a
    wrong flow curve (a local minimum). When stage 2 moves the dead band away
    from the scan's pick, the scan runs again with the other parameters as
    fitted (stage 2 again if it finds a lower cost elsewhere).
    """
    mine = tuple(p.name for p in model.AXIS_PARAMS[axis])
    names = tuple(n for n in options.params if n in mine) if options.params else mine
    first = tuple(n for n in names if n.startswith("valve_") and n.split(".")[1] in _STAGE1)
    full = Problem(axis, base, records, replace(options, params=names))
    if not {f"{'valve_' + axis}.Q_n", f"valve_{axis}.{model.DEAD_BAND}"} <= set(first):
        return full.solve(None, log)
    stage()
    mech = starts.mechanical_start(axis, base, records, names, log)
    base1 = base
    if mech:  # the flow-curve stage sees the mechanics the motions show, not the catalogue's
        p_mech = tuple(p for p in model.AXIS_PARAMS[axis] if p.name in mech)
        base1 = model.apply(base, p_mech, [mech[p.name] for p in p_mech])
    log(f"  {axis}: stage 1, the valve's flow curve ({', '.join(first)})")
    start, _ = _flow_curve_start(axis, base1, records, options, first, {}, log)
    settle = _settle_options(options, axis)
    if mech:  # the rest settles around the pinned mechanics first, then everything moves
        for group in _settling_groups(axis, names, mech):
            log(f"  {axis}: stage 2a, {', '.join(group)} (the mechanics pinned)")
            held = Problem(
                axis,
                base1,
                records,
                replace(settle, params=group),
                every=options.settle_every,
                coarse=True,
            ).solve(start, log)
            start = {**start, **held.start()}
    start.update(mech)
    stage()
    log(f"  {axis}: stage 2, every parameter (on {options.settle_segment_s:g} s segments first)")
    fit = _continued(full, start, log)
    # The scan saw the other parameters at their start values; when stage 2 moved the dead
    # band away from its pick, those biased it (a wrong inertia, say): scan again with the
    # fitted values, and run stage 2 once more if that finds a lower cost elsewhere.
    db = f"valve_{axis}.{model.DEAD_BAND}"
    d_fit = fit.value[fit.names.index(db)]
    if abs(d_fit - start[db]) <= 0.01:
        return fit
    others = [p for p in model.AXIS_PARAMS[axis] if p.name in names and p.name not in first]
    fitted = dict(zip(fit.names, fit.value))
    base2 = model.apply(base, tuple(others), [fitted[p.name] for p in others])
    offs = fit.offset_start()
    stage()
    log(f"  {axis}: stage 1 again, the other parameters as fitted")
    start2, cost2 = _flow_curve_start(axis, base2, records, options, first, offs, log)
    if cost2 >= fit.cost or abs(start2[db] - d_fit) <= 0.005:
        return fit
    log(f"  {axis}: stage 2 again, from dead band {start2[db]:+.3f} V")
    fit2 = _continued(full, {**fitted, **offs, **start2}, log)
    return fit2 if fit2.cost < fit.cost else fit


def _continued(
    prob: Problem,
    start: dict[str, float],
    log: Callable[[str], None],
    go_on: Callable[[AxisFit], bool] | None = None,
) -> AxisFit | None:
    """``prob`` solved as a continuation in the shooting segments' length: first on every
    ``settle_every``-th segment of ``settle_segment_s`` (a basin to start from, at half the
    replay), then on its own segments, from there -- unless ``go_on(first pass)`` says no
    (then None).

    Over a replay of seconds a few % of inertia or friction (the equation-error start's
    error) moves the speed so far that the flow scale, supply and leakage absorb it in a
    valley of their own (issue 21's f^0.7 plant's motor: p_s +17 %, cost 8.05 against 3.14
    at the truth's optimum), and a curve stage started against its bounds stops in one
    (plant B: 438 against 8.3). Short segments restart from the measured state before such
    an error grows, so their cost is nearly convex about the truth (Bock & Plitt, IFAC
    1984: why multiple shooting); the long segments then weigh what only they see.
    """
    settle = _settle_options(prob.options, prob.axis)
    short = Problem(
        prob.axis,
        prob.base,
        prob.records,
        settle,
        every=settle.settle_every,
        extra=prob.extra,
        coarse=True,
    ).solve(start, log)
    if go_on is not None and not go_on(short):
        return None
    fit = prob.solve(short.start(), log)
    return replace(
        fit,
        cost_start=short.cost_start,
        nfev=fit.nfev + short.nfev,
        wall_s=fit.wall_s + short.wall_s,
    )


def _settle_options(options: FitOptions, axis: str) -> FitOptions:
    """``options`` with the axis's segments ``settle_segment_s`` long (a solve's first pass)."""
    return replace(options, segment_s={**options.segment_s, axis: options.settle_segment_s})


def refit(axis: str, base, records: list[Record], fit: AxisFit, options: FitOptions | None = None):
    """The least squares of ``fit``'s parameters on other ``records``, from ``fit``'s values
    (the offsets from 0): the stage-2 fit alone, as :func:`fit_axis` ends."""
    options = replace(options or FitOptions(), params=tuple(fit.names))
    knots = tuple(p for p in fit.fit_params if model.is_handle(p.name))
    if knots:  # the handles mean what they meant in the fit: about the curve it started from
        from pneu_control.sysid.curve import with_curve_of

        base = with_curve_of(base, fit.about, fit.curve_support.valve)
    problem = Problem(axis, base, records, options, extra=knots)
    return problem.solve(dict(zip(fit.names, fit.value)), lambda _m: None)


def with_replicate(fit: AxisFit, draws: list[AxisFit]) -> AxisFit:
    """``fit`` with the parametric-bootstrap draws (:mod:`pneu_control.sysid.replicate`): per
    parameter σ² = σ_fit² + mean(d²), d = draw − fit, and the 95 % quantile of Student's t
    with as many degrees of freedom as draws (the draws are what the scatter is estimated
    from: with B of them e/σ ~ t_B)."""
    from scipy.stats import t as student_t

    d = np.array([[a - v for a, v in zip(dr.value, fit.value)] for dr in draws])
    ms = np.mean(d * d, axis=0)
    sigma = [float(np.sqrt(s * s + m)) for s, m in zip(fit.sigma, ms)]
    return replace(
        fit,
        sigma=sigma,
        sigma_fit=list(fit.sigma),
        replicate_shift=[float(v) for v in np.sqrt(ms)],
        q95=float(student_t.ppf(0.975, len(draws))),
    )


MOTOR_VOLUMES = ("rotary.V_m1", "rotary.V_m2")


def in_polytropic_index(fit: AxisFit, n: float, rel_sigma_n: float = 0.0) -> AxisFit:
    """The motor's ``fit``, made at its plant's polytropic index, written for the index ``n``
    (relative 1 σ ``rel_sigma_n``).

    The motor sees n only as n/V_m1 and n/V_m2 (Eq. 4 at its fixed volumes: the kernel's
    c = n R T0 / V), so its volumes -- values, σ and the fitted plant -- scale by n / n_fit
    and the twin is the same (its bounds were read at n_fit); what it identifies is V/n, so
    a volume's relative variance gains n's."""
    k = n / fit.plant.ambient.n_poly
    if fit.axis != "rotary" or (k == 1.0 and rel_sigma_n == 0.0):
        return fit
    f = [k if name in MOTOR_VOLUMES else 1.0 for name in fit.names]

    def scaled(xs: list[float]) -> list[float]:
        return [x * g for x, g in zip(xs, f)] if xs else xs

    value = scaled(fit.value)
    sigma = [
        math.hypot(s, v * rel_sigma_n) if name in MOTOR_VOLUMES else s
        for name, s, v in zip(fit.names, scaled(fit.sigma), value)
    ]
    rot = fit.plant.rotary
    plant = with_updates(
        fit.plant, {"ambient.n_poly": n, "rotary.V_m1": rot.V_m1 * k, "rotary.V_m2": rot.V_m2 * k}
    )
    return replace(
        fit,
        value=value,
        sigma=sigma,
        sigma_fit=scaled(fit.sigma_fit),
        sigma_iid=scaled(fit.sigma_iid),
        replicate_shift=scaled(fit.replicate_shift),
        plant=plant,
    )


def _flow_curve_start(axis, base, records, options, first, offsets, log):
    """Stage 1 on ``base``: the start values of the flow curve (and offsets) and their cost."""
    long_ = Problem(axis, base, records, replace(options, params=first))
    short = Problem(
        axis,
        base,
        records,
        replace(options, params=first, segment_s={axis: options.short_segment_s}),
        every=options.short_every,
        coarse=True,
    )
    z, cost = _scan_dead_band(long_, short, log, offsets)
    vals, offs = long_.unpack(z)
    start = dict(zip(first, vals))
    start.update(long_.offset_start(offs))
    return start, cost


_STAGE1 = ("Q_n", model.DEAD_BAND, "leak_fraction")


class Problem:
    """The least-squares problem of one axis: parameters (as z), residuals, solve, statistics
    (also what the per-segment check of :mod:`pneu_control.sysid.groups` replays)."""

    def __init__(
        self,
        axis: str,
        base,
        records: list[Record],
        options: FitOptions,
        every: int = 1,
        select: Callable[[object], bool] | None = None,
        extra: tuple[model.FitParam, ...] = (),
        coarse: bool = False,
    ):
        """``every``: every n-th replayed segment only; ``select``: only the segments whose
        design segment (:class:`pneu_control.sysid.design.Segment`) it accepts; ``extra``:
        parameters beyond the axis's own (a valve's curve knots); ``coarse``: the replays at
        ``options.basin_n_sub`` substeps (a search for a basin: at 5 instead of 10 the outputs
        move by a tenth of the sensors' noise, docs/calibration.md)."""
        if coarse and options.basin_n_sub and options.basin_n_sub < base.sim.n_sub:
            base = with_updates(base, {"sim.n_sub": options.basin_n_sub})
        self.axis, self.base, self.options = axis, base, options
        self.records, self.extra = records, tuple(extra)
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # the latest (z, residuals)
        known = model.AXIS_PARAMS[axis] + tuple(extra)
        self.params = tuple(p for p in known if p.name in options.params)
        self.p0 = [model.base_value(base, p) for p in self.params]
        bounds = []
        for p, b in zip(self.params, self.p0):
            lo, hi = p.lo, p.hi
            if p.name.endswith("." + model.DEAD_BAND):
                table = getattr(base, p.name.split(".")[0]).du_table
                lo, hi = max(lo, -0.95 * table[1]), min(hi, 5.0 - table[-1])
            bounds.append((p.to_z(lo, b), p.to_z(hi, b)))
        used = []
        for r in records:
            seg = shooting.segments_of(r, axis, options.segment_s[axis])
            if every > 1:
                seg = shooting.Segments(seg.starts[::every], seg.lengths[::every])
            d = r.designs.get(axis)
            if select is not None and d is not None:
                t0 = seg.starts * r.period_s + 1e-9
                m = np.array([select(d.segments[d.segment_at(t)]) for t in t0], dtype=bool)
                seg = shooting.Segments(seg.starts[m], seg.lengths[m])
            elif select is not None:
                seg = shooting.Segments(seg.starts[:0], seg.lengths[:0])
            if len(seg):
                used.append((r, seg))
        if not used:
            raise ValueError(
                f"{axis}: no usable data in the bags (axis not excited or all invalid)"
            )
        self.used = used
        self.signals = AXIS_SIGNALS[axis]
        self.pnames = _PRESSURE_OF[axis]
        self.scale = {}
        for name in self.signals:  # the signals' spreads: fixed residual weights
            vals = np.concatenate([r.y[name][s.index] for r, s in used])
            self.scale[name] = float(np.std(vals)) or 1.0
        self.n_p = len(self.params)
        self.n_off = len(self.pnames) * len(used)
        dec = options.decimate
        self.meas = [{n: r.y[n][s.index][::dec] for n in self.signals} for r, s in used]
        # the replayed segment (cluster) of each residual row, over all the signals of a record
        ids, c0 = [], 0
        for _r, s in used:
            seg_id = np.repeat(np.arange(len(s)), s.lengths)[::dec] + c0
            c0 += len(s)
            ids.extend(seg_id for _ in self.signals)
        self.cluster, self.n_clusters = np.concatenate(ids), c0
        self.pivot = _pivots(axis, base, self.params, used)
        ob = OFFSET_BOUND_PA / _OFFSET_WIDTH
        self.lo = np.array([b[0] for b in bounds] + [-ob] * self.n_off)
        self.hi = np.array([b[1] for b in bounds] + [ob] * self.n_off)

    def unpack(self, z: np.ndarray) -> tuple[list[float], list[dict[str, float]]]:
        n_p, k = self.n_p, len(self.pnames)
        vals = [
            min(max(p.from_z(float(zi), b), p.lo), p.hi)  # rounding at a bound
            for p, zi, b in zip(self.params, z[:n_p], self.p0)
        ]
        for i_q, factor in self.pivot:  # Q_n from the pivot flow, dead band and supply
            vals[i_q] = vals[i_q] * factor(vals)
        offs = []
        for j in range(len(self.used)):
            zo = z[n_p + j * k : n_p + (j + 1) * k]
            offs.append({name: float(v) * _OFFSET_WIDTH for name, v in zip(self.pnames, zo)})
        return vals, offs

    def offset_start(self, offs: list[dict[str, float]]) -> dict[str, float]:
        return {
            f"offset:{r.path}:{k}": v for (r, _s), o in zip(self.used, offs) for k, v in o.items()
        }

    def z_start(self, start: dict[str, float] | None) -> np.ndarray:
        z = np.zeros(self.n_p + self.n_off)
        if start:
            vals = [start.get(p.name, b) for p, b in zip(self.params, self.p0)]
            for i_q, factor in self.pivot:
                vals[i_q] = vals[i_q] / factor(vals)
            for i, (p, b) in enumerate(zip(self.params, self.p0)):
                z[i] = p.to_z(vals[i], b)
            k = len(self.pnames)
            for j, (rec, _s) in enumerate(self.used):
                for q, name in enumerate(self.pnames):
                    z[self.n_p + j * k + q] = (
                        start.get(f"offset:{rec.path}:{name}", 0.0) / _OFFSET_WIDTH
                    )
        return np.clip(z, self.lo, self.hi)

    def residuals(self, z: np.ndarray) -> np.ndarray:
        vals, offs = self.unpack(z)
        plant = model.apply(self.base, self.params, vals)
        sims = [shooting.simulate(plant, r, s, off, self.axis) for (r, s), off in zip(self.used, offs)]  # fmt: skip
        return self._stack(sims)

    def _stack(self, sims: list[dict[str, np.ndarray]]) -> np.ndarray:
        """The weighted residual vector of the records' simulated signals."""
        parts = []
        dec = self.options.decimate
        for m, sim in zip(self.meas, sims):
            for name in self.signals:
                parts.append((m[name] - sim[name][::dec]) / self.scale[name])
        return np.concatenate(parts)

    def jacobian(self, z: np.ndarray) -> np.ndarray:
        """least_squares' own 2-point Jacobian (scipy's ``approx_derivative`` with its steps
        and bounds: the same bits as ``jac="2-point"``), each column's replay started again
        from the first period its change can act in (:func:`shooting.simulate_from`: a curve
        knot acts only where the valve opens that far)."""
        vals, offs = self.unpack(z)
        plant = model.apply(self.base, self.params, vals)
        kept = [shooting.trace(plant, r, s, off, self.axis) for (r, s), off in zip(self.used, offs)]  # fmt: skip

        def column(x: np.ndarray) -> np.ndarray:
            vals_x, offs_x = self.unpack(x)
            plant_x = model.apply(self.base, self.params, vals_x)
            return self._stack([shooting.simulate_from(plant_x, t, o) for (_, t), o in zip(kept, offs_x)])  # fmt: skip

        f0 = self._stack([sim for sim, _ in kept])
        return self._differences(column, z, f0)

    def _plain_jacobian(self, z: np.ndarray) -> np.ndarray:
        """least_squares' own 2-point Jacobian of :meth:`residuals` (the same bits as
        ``jac="2-point"``), its columns on the replay's workers."""
        last = self._last
        f0 = last[1] if last is not None and np.array_equal(last[0], z) else self.residuals(z)
        return self._differences(self.residuals, z, f0)

    def _differences(self, fn, z: np.ndarray, f0: np.ndarray) -> np.ndarray:
        """scipy's ``approx_derivative`` of ``fn`` at ``z`` (2-point, least_squares' steps and
        bounds), one column a task on the replay's workers (:mod:`pneu_sim.physics.workers`)."""
        from scipy.optimize._numdiff import approx_derivative  # what least_squares calls

        return approx_derivative(
            fn,
            z,
            method="2-point",
            rel_step=self.options.diff_step,
            f0=f0,
            bounds=(self.lo, self.hi),
            workers=workers.map_tasks,
        )

    def cost(self, z: np.ndarray) -> float:
        r = self.residuals(z)
        return 0.5 * float(r @ r)

    def solve(self, start: dict[str, float] | None, log: Callable[[str], None]) -> AxisFit:
        axis, params = self.axis, self.params
        z0 = self.z_start(start)
        t0 = time.perf_counter()
        r0 = self.residuals(z0)
        cost0 = 0.5 * float(r0 @ r0)
        n_eval = [0]
        # a curve knot's column replays from where the valve first opens that far: the
        # shared Jacobian; without knots every column replays whole and the trace would
        # only cost (scipy's own differences, the same bits either way)
        shared = any(model.is_handle(p.name) for p in params)

        def tracked(z):
            n_eval[0] += 1
            r = self.residuals(z)
            self._last = (z.copy(), r)  # what the Jacobian at z differences against
            vals, _ = self.unpack(z)
            shown = ", ".join(f"{p.name.split('.', 1)[-1]}={v:.4g}" for p, v in zip(params, vals))
            log(
                f"  {axis} eval {n_eval[0]:4d}  cost {0.5 * float(r @ r):.5g}  "
                f"({time.perf_counter() - t0:.0f} s)  {shown}"
            )
            return r

        res = self._least_squares(tracked, z0, self.jacobian if shared else self._plain_jacobian)
        return self._statistics(res, cost0, time.perf_counter() - t0)

    def _least_squares(self, fun, z0: np.ndarray, jacobian) -> object:
        """scipy's trust-region reflective least squares within the bounds, its Jacobian by
        differences (``jacobian``) only at the start, every ``jacobian_every``-th accepted
        step and after a step the Jacobian mispredicted (the cost fell by less than a quarter
        of what it promised); between, Broyden's rank-one secant update from every point
        evaluated (Broyden 1965, as in Madsen, Nielsen & Tingleff, *Methods for non-linear
        least squares problems*, 2004, sec. 3.4). A Jacobian by differences costs a replay per
        parameter; an update, none.

        A step so small that trf may stop on it gets a fresh Jacobian; a solve that trf
        stops on a step taken from an updated one (its steps may have shrunk on the
        update's error, not at the optimum) starts again from there on a fresh one. The
        result carries a fresh Jacobian at the optimum (the statistics read it).
        ``jacobian_every`` = 1 is plain trf."""
        from scipy.optimize import least_squares

        opt = self.options
        seen: list[tuple[np.ndarray, np.ndarray]] = []  # evaluated since the last Jacobian
        # J at (x, f); fresh: by differences; age: updates since; trial: a fresh J's step
        now: dict = {"x": None, "f": None, "J": None, "fresh": False, "age": 0, "trial": True}

        def evaluated(z: np.ndarray) -> np.ndarray:
            r = fun(z)
            now["trial"] = now["J"] is None or now["fresh"]
            seen.append((z.copy(), r))
            return r

        def differenced(z: np.ndarray, f: np.ndarray) -> np.ndarray:
            now.update(x=z.copy(), f=f, J=jacobian(z), fresh=True, age=0)
            return now["J"]

        def jac(z: np.ndarray) -> np.ndarray:
            f = next(r for x, r in reversed(seen) if np.array_equal(x, z))
            J0, x0, f0 = now["J"], now["x"], now["f"]
            seen_now = list(seen)
            seen.clear()
            if J0 is not None and np.array_equal(x0, z):  # a restart where the last solve ended
                J = J0 if now["fresh"] else differenced(z, f)
                now["trial"] = True  # a stop before any step is a stop on a fresh Jacobian
                return J
            stale = J0 is None or now["age"] + 1 >= opt.jacobian_every
            if not stale:
                c0, c = float(f0 @ f0), float(f @ f)
                lin = f0 + J0 @ (z - x0)
                promised = c0 - float(lin @ lin)
                # mispredicted, or a step so small that trf may stop here: a fresh one
                stale = promised <= 0.0 or c0 - c < 0.25 * promised or c0 - c <= opt.ftol * c0
            if stale:
                return differenced(z, f)
            J = J0.copy()
            for x, r in seen_now:  # each evaluated point's secant, in turn
                dx = x - x0
                dd = float(dx @ dx)
                if dd > 0.0:
                    J += np.outer(r - f0 - J @ dx, dx / dd)
            now.update(x=z.copy(), f=f, J=J, fresh=False, age=now["age"] + 1)
            return J

        z, nfev = z0, 0
        while True:
            res = least_squares(
                evaluated,
                z,
                bounds=(self.lo, self.hi),
                jac=jac,
                method="trf",
                x_scale=1.0,
                max_nfev=max(opt.max_nfev - nfev, 1),
                xtol=opt.xtol,
                ftol=opt.ftol,
            )
            nfev += res.nfev
            res.nfev = nfev
            # trf stopped on a step it took from an updated Jacobian (its steps may have
            # shrunk on the update's error): again from there, on a fresh one
            if now["trial"] or nfev >= opt.max_nfev:
                if not (now["fresh"] and np.array_equal(now["x"], res.x)):
                    res.jac = jacobian(res.x)
                return res
            z = res.x

    def _statistics(self, res, cost0: float, wall: float) -> AxisFit:
        n_p = self.n_p
        J, r = res.jac, res.fun
        m_res, p_all = J.shape
        s2 = float(r @ r) / max(m_res - p_all, 1)
        taus = []  # residual autocorrelation, per record and signal, along time
        k = 0
        for m in self.meas:
            for name in self.signals:
                n = m[name].size
                taus.append(_autocorr_time(r[k : k + n]))
                k += n
        infl = float(np.median(taus)) if taus else 1.0
        A_inv = np.linalg.pinv(J.T @ J)
        cov_iid = A_inv * s2 * infl
        cov_z = _segment_sandwich(A_inv, J, r, self.cluster, self.n_clusters)
        sd_z = np.sqrt(np.maximum(np.diag(cov_z), 0.0))
        vals, offs = self.unpack(res.x)
        # the parameters' covariance through the (pivoted) map z -> p, to first order
        G = np.zeros((n_p, n_p))
        for i in range(n_p):
            dz = np.zeros_like(res.x)
            dz[i] = 1e-6
            up, _ = self.unpack(res.x + dz)
            dn, _ = self.unpack(res.x - dz)
            G[:, i] = (np.array(up) - np.array(dn)) / 2e-6
        cov_p = G @ cov_z[:n_p, :n_p] @ G.T
        sigma = [float(v) for v in np.sqrt(np.maximum(np.diag(cov_p), 0.0))]
        sigma_iid = np.sqrt(np.maximum(np.diag(G @ cov_iid[:n_p, :n_p] @ G.T), 0.0))
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = cov_p / np.outer(sigma, sigma)
        corr[~np.isfinite(corr)] = 0.0  # a value without effect (σ = 0) correlates with none
        offsets, offsets_sigma = {}, {}
        kk = len(self.pnames)
        for j, ((rec, _s), off) in enumerate(zip(self.used, offs)):
            offsets[rec.path] = off
            offsets_sigma[rec.path] = {
                name: float(sd_z[n_p + j * kk + q] * _OFFSET_WIDTH)
                for q, name in enumerate(self.pnames)
            }
        return AxisFit(
            axis=self.axis,
            names=[p.name for p in self.params],
            units=[p.unit for p in self.params],
            base=self.p0,
            value=vals,
            sigma=sigma,
            corr=corr,
            offsets=offsets,
            offsets_sigma=offsets_sigma,
            cost_start=cost0,
            cost=float(res.cost),
            nfev=int(res.nfev),
            wall_s=wall,
            inflation=infl,
            n_residuals=m_res,
            status=str(res.message),
            sigma_iid=[float(v) for v in sigma_iid],
            n_clusters=self.n_clusters,
            plant=model.apply(self.base, self.params, vals),
            fit_params=self.params,
            about=self.base,
        )


def _segment_sandwich(
    A_inv: np.ndarray, J: np.ndarray, r: np.ndarray, cluster: np.ndarray, n_clusters: int
) -> np.ndarray:
    """Cluster-robust covariance of the least-squares estimate, one cluster per replayed
    segment: (JᵀJ)⁻¹ (Σ_g J_gᵀ r_g r_gᵀ J_g) (JᵀJ)⁻¹ · G/(G − 1) (Liang & Zeger 1986; the
    small-sample factor of Cameron & Miller 2015, sec. VI).

    Within a segment the residuals are anything but independent (one start error runs
    through the whole replay, a model error too); between segments they are nearly so. The
    sandwich takes their covariance from the segments' own scores, whatever its form, so it
    also widens with a model error that pulls different segments different ways."""
    S = np.zeros((n_clusters, J.shape[1]))
    np.add.at(S, cluster, J * r[:, None])
    g = max(n_clusters, 2)
    return A_inv @ (S.T @ S) @ A_inv * (g / (g - 1))


def _scan_dead_band(
    long_: Problem, short: Problem, log: Callable[[str], None], offsets: dict[str, float]
) -> tuple[np.ndarray, float]:
    """The flow curve's start: the dead band by a scan along the cost's valley.

    Every (Q_n, dead band) pair that gives the right flow where the valve mostly
    ran lies in one long valley. Over a replay of seconds (``long_``) the true
    pair sits in a narrow pit in it (the flow near the dead-band edge is very
    sensitive); over short replays (``short``, 0.2 s) the valley is smooth. So
    at each dead band on a grid (every 25 mV over the allowed range, then every
    5 mV about the best; the fine steps fixed from the coarse best) the pivot flow, the centre leakage (it acts where the
    dead band does, near 5 V) and the pressure offsets go to the smooth
    valley's floor (damped Gauss-Newton steps on ``short``: converged at the
    start's dead band, then warm-started point to point walking away from it
    both ways -- a continuation along the valley) and the
    long replay's cost scores the point; the best point starts stage 2.
    """
    i_d = [p.name for p in short.params].index(f"valve_{short.axis}.{model.DEAD_BAND}")
    w = short.params[i_d].width
    lo, hi = short.lo, short.hi
    z = short.z_start(offsets)
    t0 = time.perf_counter()

    # the pivot flow, the other stage-1 parameters (the centre leakage) and the offsets
    free = [i for i in range(short.n_p) if i != i_d] + list(
        range(short.n_p, short.n_p + short.n_off)
    )

    def floor(zd: float, z: np.ndarray, steps: int = 2) -> np.ndarray:
        return _valley_floor(short, i_d, free, zd, z, steps)

    # continuation: converge at the start's dead band, then walk the valley floor both ways
    z0 = floor(float(np.clip(z[i_d], lo[i_d], hi[i_d])), z, steps=5)
    best = (long_.cost(z0), z0)
    coarse = 0.025 / w
    for direction in (1.0, -1.0):
        z = z0
        zd = z0[i_d] + direction * coarse
        while lo[i_d] - 1e-9 <= zd <= hi[i_d] + 1e-9:
            z = floor(float(zd), z)
            cost = long_.cost(z)
            if cost < best[0]:
                best = (cost, z.copy())
            zd += direction * coarse
    log(
        f"  {long_.axis}: dead band scan every 25 mV: best {best[1][i_d] * w:+.3f} V, "
        f"cost {best[0]:.5g} ({time.perf_counter() - t0:.0f} s)"
    )
    centre = best[1]
    for direction in (1.0, -1.0):  # then every 5 mV about the best
        z = centre
        for k in (1, 2, 3):
            zd = float(np.clip(centre[i_d] + direction * k * 0.005 / w, lo[i_d], hi[i_d]))
            z = floor(zd, z)
            cost = long_.cost(z)
            if cost < best[0]:
                best = (cost, z.copy())
    log(
        f"  {long_.axis}: dead band scan every 5 mV: best {best[1][i_d] * w:+.3f} V, "
        f"cost {best[0]:.5g} ({time.perf_counter() - t0:.0f} s)"
    )
    return best[1], best[0]


def _valley_floor(
    short: Problem, i_d: int, free: list[int], zd: float, z: np.ndarray, steps: int
) -> np.ndarray:
    """``z`` with the dead band at ``zd`` and the ``free`` coordinates on ``short``'s valley
    floor: ``steps`` damped Gauss-Newton steps (the difference columns on the replay's
    workers)."""
    lo, hi = short.lo, short.hi
    z = z.copy()
    z[i_d] = zd
    r = short.residuals(z)
    for _ in range(steps):
        J = np.empty((len(r), len(free)))
        shifted = []
        for i in free:
            zq = z.copy()
            zq[i] += 1e-2
            shifted.append(zq)
        for c, r_c in enumerate(workers.map_tasks(short.residuals, shifted)):
            J[:, c] = (r_c - r) / 1e-2
        # damped (Levenberg) and limited: a direction the short replays hardly see
        # (the cylinder's slow leakage) must not run away
        JtJ = J.T @ J
        damp = 1e-3 * np.diag(np.diag(JtJ)) + 1e-12 * np.eye(len(free))
        step = np.clip(np.linalg.solve(JtJ + damp, -J.T @ r), -1.0, 1.0)
        z[free] = np.clip(z[free] + step, lo[free], hi[free])
        r = short.residuals(z)
    return z


def _pivots(axis: str, base, params, used) -> list[tuple[int, Callable[[list[float]], float]]]:
    """Decouple a valve's flow scale from its dead band and its supply pressure.

    With flow = Q_n · table(du − db), every (Q_n, db) pair that gives the same
    flow at the voltages the rig mostly ran at lies in one long curved valley
    of the cost; and the choked flow of Eq. 11 goes with Q_n · p_s, a second
    valley. So the fit moves Q_eff, the flow at the pivot du_ref (the median
    |u − 5 V| of the records, outside the dead band) at the start's supply, and
    Q_n = Q_eff · table(du_ref) / table(du_ref − db) · p_s0 / p_s: the dead
    band rotates the curve about the pivot, a supply change keeps the choked
    flow. Returns (index of Q_n, factor(values)) pairs.
    """
    names = [p.name for p in params]
    valve = "valve_" + axis
    q, d = f"{valve}.Q_n", f"{valve}.{model.DEAD_BAND}"
    if q not in names:
        return []
    supply = f"supply.p_s_{axis}"
    i_d = names.index(d) if d in names else None
    i_s = names.index(supply) if supply in names else None
    v = getattr(base, valve)
    du_t, fl_t = np.asarray(v.du_table), np.asarray(v.flow_table)
    du = np.concatenate([np.abs(r.u[axis] - 5.0) for r, _s in used])
    du = du[du > du_t[1] + 0.05]
    du_ref = float(np.median(du)) if len(du) else float(du_t[len(du_t) // 2])
    f_ref = float(np.interp(du_ref, du_t, fl_t))
    p_s0 = float(getattr(base.supply, f"p_s_{axis}"))

    def factor(vals: list[float]) -> float:
        f = 1.0
        if i_d is not None:
            f *= f_ref / max(float(np.interp(du_ref - vals[i_d], du_t, fl_t)), 1e-6)
        if i_s is not None:
            f *= p_s0 / vals[i_s]
        return f

    return [(names.index(q), factor)]
