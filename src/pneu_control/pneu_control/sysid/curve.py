"""A valve's own flow-vs-voltage curve as fit parameters: per port, a dead band and monotone knots.

The twin takes a curve per port (:mod:`pneu_sim.physics.valve_curve`: signed
normalised flow f(u), port 4 non-decreasing, port 2 non-increasing). Here
each port the plumbing uses is written g = σ f (σ = +1 port 4, −1 port 2: g
non-decreasing) and parametrised by

- ``<valve>.flow_<port>@null`` (V): the centre c of the port's dead band
  (the null offset), and ``@band`` (V, ≥ 0): its half-width w. g = 0 on
  [5 + c − w, 5 + c + w] (the centre leak still flows there);
- ``<valve>.flow_<port>@±δ``: the increment of g from the next knot inward
  to the knot δ beyond the dead band's edge on that side (≥ 0: monotone by
  construction), at δ = :data:`KNOTS_DV`; between knots the curve keeps the
  start curve's shape (at the start's values it is the start curve).

The knots ride on the edges: the flow is most sensitive to the voltage just
past the dead band (a fixed grid there needs 50 mV spacing to replay the
twin right; measured), so the edges are parameters and a few knots carry the
shape. Every |f| ≤ :data:`~pneu_sim.physics.valve_curve.FLOW_BOUND`.

A knot is fitted only where the data inform it: at least :data:`MIN_SAMPLES`
valid samples with the valve command between it and the next knot inward
(contiguous from the dead band). Beyond the last fitted knot of a side the
start curve's shape is kept, its difference from the fitted knot fading out
to none at full opening (there the catalogue's nominal flow, which the data
do not reach, holds), and the provenance says so. A port the plumbing does not
use (port 2 of the motor's valve in the paper's plumbing) is written as port
4's image, f_2 = −f_4 (the same spool), and said so.
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass, field

import numpy as np
from pneu_msgs_py.params.core import with_updates
from pneu_sim.physics.valve_curve import FLOW_BOUND, grid, port_curves

from pneu_control.sysid.model import FitParam, is_handle

__all__ = [
    "KNOTS_DV",
    "MIN_SAMPLES",
    "CurveSupport",
    "base_value",
    "fit_params",
    "is_handle",
    "max_error",
    "own_curve_plant",
    "ports_of",
    "updates",
    "with_curve_of",
]

KNOTS_DV = (0.1, 0.25, 0.45, 0.7, 1.0, 1.4, 1.9, 2.6, 3.3, 4.0, 4.7)  # V beyond a dead band's edge
MIN_SAMPLES = 100  # valid samples (0.1 s) between a knot and the next inward to fit it
EDGE_FLOW = 1e-4  # g below which the start curve counts as inside its dead band (the closing path's leak fades over g 0-0.01: a coarser edge moves the null's leak balance)
_WIDTH_V = 0.05  # fit coordinate of the edges: z = 1 is 50 mV
_WIDTH_G = 0.02  # ... of the increments: z = 1 is 2 % of full flow
_SIGN = {"4": 1.0, "2": -1.0}
_DENSE = np.round(np.arange(0.0, 10.0 + 1e-9, 0.05), 2)  # V: the start curve's grid


def _parse(name: str) -> tuple[str, str, str]:
    head, what = name.split("@")
    valve, leaf = head.split(".")
    return valve, leaf[-1], what


def ports_of(axis: str, base) -> tuple[str, ...]:
    """The valve ports the axis's plumbing uses (the motor's port 2 only when bidirectional)."""
    if axis == "rotary" and base.rotary.plumbing != "bidirectional":
        return ("4",)
    return ("4", "2")


def _memo(fn):
    """``fn`` memoised on its (frozen, hashable) arguments; called afresh on unhashable ones
    (a params object built directly with lists, not through the loader)."""
    cached = functools.lru_cache(maxsize=64)(fn)

    @functools.wraps(fn)
    def call(*args):
        try:
            hash(args)
        except TypeError:
            return fn(*args)
        return cached(*args)

    return call


@_memo
def _curves(v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`port_curves` of the valve params ``v``, read-only: a fit reads the start
    curve's shape thousands of times, once per Jacobian column."""
    out = port_curves(v)
    for a in out:
        a.setflags(write=False)
    return out


def _g(v, port: str, u: np.ndarray) -> np.ndarray:
    """σ f of ``port`` of valve params ``v`` at voltages ``u`` (non-decreasing)."""
    uu, f4, f2 = _curves(v)
    return _SIGN[port] * np.interp(u, uu, f4 if port == "4" else f2)


@_memo
def _edges(v, port: str) -> tuple[float, float]:
    """(centre c, half-width w) of the start curve's dead band, V (|g| <= EDGE_FLOW)."""
    g = _g(v, port, _DENSE)
    hi = _DENSE[g <= EDGE_FLOW]
    lo = _DENSE[g >= -EDGE_FLOW]
    e_hi = float(hi.max()) if len(hi) else 5.0
    e_lo = float(lo.min()) if len(lo) else 5.0
    if e_lo > e_hi:
        e_lo = e_hi = 0.5 * (e_lo + e_hi)
    return 0.5 * (e_lo + e_hi) - 5.0, 0.5 * (e_hi - e_lo)


def _knot_u(c: float, w: float, side: str) -> np.ndarray:
    """The knots' voltages on ``side`` of the dead band (c, w), outward, inside 0-10 V."""
    d = np.asarray(KNOTS_DV)
    u = 5.0 + c + w + d if side == "+" else 5.0 + c - w - d
    return u[(u > 0.0) & (u < 10.0)]


@dataclass
class CurveSupport:
    """What the data inform of one valve's curve: per port and side the fitted knots, and the
    samples and design segments behind them."""

    valve: str
    ports: tuple[str, ...]
    knots: dict[tuple[str, str], int] = field(default_factory=dict)  # (port, side) -> fitted
    reach: dict[tuple[str, str], float] = field(default_factory=dict)  # ... -> outermost V
    samples: int = 0  # valid samples with the command inside the fitted range
    segments: dict[str, int] = field(default_factory=dict)  # design segment kind -> count

    def fitted_range(self) -> dict[str, tuple[float, float]]:
        """port -> (lo, hi) V: the voltages its fitted knots span (the dead band's edges if
        none)."""
        return {
            p: (self.reach.get((p, "-"), 5.0), self.reach.get((p, "+"), 5.0)) for p in self.ports
        }

    def text(self) -> str:
        """One phrase: the range fitted and what it rests on."""
        kinds = ", ".join(f"{n} {k}" for k, n in sorted(self.segments.items())) or "no design"
        lo = min((self.reach.get((p, "-"), 5.0) for p in self.ports), default=5.0)
        hi = max((self.reach.get((p, "+"), 5.0) for p in self.ports), default=5.0)
        return (
            f"dead band and knots fitted over {lo:.2f}-{hi:.2f} V from {self.samples} samples "
            f"({kinds} segments); beyond, the catalogue's shape, meeting its full flow at full "
            "opening (no data there)"
        )


def fit_params(axis: str, start, records) -> tuple[tuple[FitParam, ...], CurveSupport]:
    """The handles of ``axis``'s valve that the valid samples of ``records`` inform, about the
    curve of ``start`` (PlantParams), and that support."""
    valve = "valve_" + axis
    v = getattr(start, valve)
    sup = CurveSupport(valve, ports_of(axis, start))
    u_all = np.concatenate([r.u[axis][r.valid[axis]] for r in records])
    lo_all, hi_all = 5.0, 5.0
    out = []
    for port in sup.ports:
        c, w = _edges(v, port)
        out.append(FitParam(f"{valve}.flow_{port}@null", axis, "lin", -1.0, 1.0, "V", f"{valve} port {port}: dead band centre (null offset) - 5 V", width=_WIDTH_V))  # fmt: skip
        out.append(FitParam(f"{valve}.flow_{port}@band", axis, "lin", 0.0, 1.5, "V", f"{valve} port {port}: dead band half-width", width=_WIDTH_V))  # fmt: skip
        for side, sgn in (("+", 1.0), ("-", -1.0)):
            inner = 5.0 + c + sgn * w
            n_fit = 0
            for d, uk in zip(KNOTS_DV, _knot_u(c, w, side)):
                between = (sgn * (u_all - inner) > 0.0) & (sgn * (u_all - uk) <= 0.0)
                if np.count_nonzero(between) < MIN_SAMPLES:
                    break
                out.append(FitParam(f"{valve}.flow_{port}@{side}{d:.2f}", axis, "lin", 0.0, 2.0 * FLOW_BOUND, "-", f"{valve} port {port}: flow increment {d:.2f} V beyond the dead band's {side} edge", width=_WIDTH_G))  # fmt: skip
                inner = uk
                n_fit += 1
            sup.knots[(port, side)] = n_fit
            sup.reach[(port, side)] = float(inner)
            lo_all, hi_all = min(lo_all, inner), max(hi_all, inner)
    sup.samples = int(np.count_nonzero((u_all >= lo_all) & (u_all <= hi_all)))
    sup.segments = _segments(axis, records, lo_all, hi_all)
    return tuple(out), sup


def _segments(axis: str, records, lo: float, hi: float) -> dict[str, int]:
    """Design segment kind -> segments with samples off the null inside [lo, hi] V."""
    out: dict[str, int] = {}
    for r in records:
        d = r.designs.get(axis)
        if d is None:
            continue
        t, u = r.t, r.u[axis]
        for s in d.segments:
            m = (t >= s.t0_s) & (t < s.t1_s) & r.valid[axis] & (u != 5.0) & (u >= lo) & (u <= hi)
            if np.count_nonzero(m) >= MIN_SAMPLES // 10:
                out[s.kind] = out.get(s.kind, 0) + 1
    return out


def base_value(start, name: str) -> float:
    """The handle's value on ``start``'s curve (dead band centre or half-width, V; or an
    outward increment of g)."""
    valve, port, what = _parse(name)
    v = getattr(start, valve)
    c, w = _edges(v, port)
    if what == "null":
        return c
    if what == "band":
        return w
    side, j = what[0], KNOTS_DV.index(float(what[1:]))
    u = _knot_u(c, w, side)
    inner = 5.0 + c + (w if side == "+" else -w) if j == 0 else u[j - 1]
    g = _g(v, port, np.array([inner, u[j]]))
    return float(abs(g[1] - g[0]))


def updates(start, values: dict[str, float]) -> dict[str, tuple[float, ...]]:
    """plant.yaml updates (``<valve>.u_curve``, ``flow_4``, ``flow_2``) from handle values,
    about the curve of ``start`` (where no knot is fitted)."""
    by: dict[str, dict[str, dict[str, float]]] = {}
    for name, val in values.items():
        valve, port, what = _parse(name)
        by.setdefault(valve, {}).setdefault(port, {})[what] = val
    out: dict[str, tuple[float, ...]] = {}
    for valve, ports in by.items():
        v = getattr(start, valve)
        curves = {}
        for port, h in ports.items():
            u, g = _port_curve(v, port, h)
            curves[port] = (u, _SIGN[port] * g)
        if "2" not in curves:  # unused by the plumbing: the same spool's image of port 4
            curves["2"] = (curves["4"][0], -curves["4"][1])
        u = np.union1d(curves["4"][0], curves["2"][0])
        out[f"{valve}.u_curve"] = tuple(float(x) for x in u)
        for port in ("4", "2"):
            f = np.interp(u, *curves[port])
            out[f"{valve}.flow_{port}"] = tuple(float(x) for x in f)
    return out


def _port_curve(v, port: str, h: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """(u, g) of one port from its handles ``h`` (see the module docstring).

    Between two fitted knots the curve follows the start curve ``v``'s shape there (mapped
    onto the knots as the edges move), so at the start's own values it is the start curve;
    beyond the last fitted knot, the start's shape with the difference fading out at full
    opening.
    """
    u_s, f4, f2 = _curves(v)
    g_s = f4 if port == "4" else f2
    c0, w0 = _edges(v, port)
    c, w = h.get("null", c0), max(h.get("band", w0), 0.0)
    us, gs = [np.array([5.0 + c - w, 5.0 + c + w])], [np.zeros(2)]
    for side, sgn in (("+", 1.0), ("-", -1.0)):
        ku = [5.0 + c + sgn * w, *_knot_u(c, w, side).tolist()]
        spans = _spans(v, port, side)
        g_prev = 0.0
        j = 0
        while j + 1 < min(len(ku), len(spans) + 1) and f"{side}{KNOTS_DV[j]:.2f}" in h:
            g_k = g_prev + sgn * h[f"{side}{KNOTS_DV[j]:.2f}"]
            t, frac = spans[j]
            a, b = ku[j], ku[j + 1]
            us.append(a + t * (b - a))
            gs.append(g_prev + (g_k - g_prev) * frac)
            us.append(np.array([b]))
            gs.append(np.array([g_k]))
            g_prev = g_k
            j += 1
        last = ku[j]  # the last fitted point (the edge if none): the start's shape beyond
        end = 10.0 if sgn > 0 else 0.0
        b_last, b_end = (float(x) for x in _SIGN[port] * np.interp([last, end], u_s, g_s))
        tail = np.append(u_s[sgn * (u_s - last) > 0.0], end)
        b_tail = _SIGN[port] * np.interp(tail, u_s, g_s)
        span = b_end - b_last
        fade = (b_end - b_tail) / span if abs(span) > 1e-12 else np.zeros(len(tail))
        us.append(tail)
        gs.append(b_tail + (g_prev - b_last) * fade)
    u, idx = np.unique(np.round(np.concatenate(us), 6), return_index=True)
    g = np.concatenate(gs)[idx]
    return u, np.clip(np.maximum.accumulate(g), -FLOW_BOUND, FLOW_BOUND)


@_memo
def _spans(v, port: str, side: str) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """Per knot interval j of ``side`` of the start curve ``v``: its inner breakpoints as
    (t, frac), the fraction of the interval's voltage and of its flow rise at each (what
    :func:`_port_curve` maps onto the moved knots; it depends on ``v`` alone)."""
    u_s = _curves(v)[0]
    c0, w0 = _edges(v, port)
    sgn = 1.0 if side == "+" else -1.0
    ku0 = [5.0 + c0 + sgn * w0, *_knot_u(c0, w0, side).tolist()]
    out = []
    for a0, b0 in itertools.pairwise(ku0):
        s_a, s_b = (float(x) for x in _g(v, port, np.array([a0, b0])))
        inner = u_s[(sgn * (u_s - a0) > 0.0) & (sgn * (u_s - b0) < 0.0)]
        t = (inner - a0) / (b0 - a0)
        frac = (_g(v, port, inner) - s_a) / (s_b - s_a) if abs(s_b - s_a) > 1e-12 else t
        for a in (t, frac):
            a.setflags(write=False)
        out.append((t, frac))
    return tuple(out)


def own_curve_plant(plant, axis: str, estimate: dict | None = None):
    """The curve stage's start: ``plant`` with its ``axis`` valve's catalogue-family curve
    (its table and dead band) written as an own curve, in units of its own Q_n (so the
    twin is the same, to the dense breakpoints).

    ``estimate``: port -> (u, g, samples behind each; NaN where none), a direct measurement
    in the same units (:func:`pneu_control.sysid.valve_flow.estimate_curve`): where it has
    values they replace ``plant``'s curve, made monotone (weighted by the samples).
    """
    from pneu_control.sysid.valve_flow import isotonic

    valve = "valve_" + axis
    u, f4, f2 = port_curves(getattr(plant, valve))
    flows = {"4": (u, f4), "2": (u, f2)}
    if estimate:
        for port in flows:
            if port not in estimate:
                continue
            eu, eg, cnt = estimate[port]
            g = _SIGN[port] * np.interp(eu, *flows[port])
            w = np.ones(len(eu))
            have = np.isfinite(eg)
            g[have], w[have] = eg[have], cnt[have]
            flows[port] = (eu, _SIGN[port] * isotonic(g, w))
    uu = np.union1d(flows["4"][0], flows["2"][0])
    upd = {f"{valve}.u_curve": tuple(float(x) for x in uu)}
    for port in ("4", "2"):
        f = np.clip(np.interp(uu, *flows[port]), -FLOW_BOUND, FLOW_BOUND)
        upd[f"{valve}.flow_{port}"] = tuple(float(x) for x in f)
    return with_updates(plant, upd)


def max_error(
    a,
    b,
    valve: str,
    ports: tuple[str, ...] = ("4", "2"),
    within: dict[str, tuple[float, float]] | None = None,
    outside: bool = False,
) -> float:
    """max over 0-10 V and ``ports`` of |flow of ``a`` − flow of ``b``|, as a fraction of
    ``b``'s full flow (each curve scaled by its valve's Q_n). ``within``: port -> (lo, hi)
    V, only there -- or, ``outside``, only outside it (0 where that leaves no voltage)."""
    va, vb = getattr(a, valve), getattr(b, valve)
    g = grid()
    worst = 0.0
    for port in ports:
        m = np.ones(g.shape, dtype=bool)
        if within is not None:
            lo, hi = within[port]
            m = (g >= lo) & (g <= hi)
            m = ~m if outside else m
        if not m.any():
            continue
        fa = _g(va, port, g[m]) * va.Q_n / vb.Q_n
        fb = _g(vb, port, g[m])
        worst = max(worst, float(np.max(np.abs(fa - fb))))
    return worst if math.isfinite(worst) else math.inf


def with_curve_of(plant, fitted, valve: str):
    """``plant`` with the curve (and its unit Q_n) of ``valve`` as in ``fitted``."""
    v = getattr(fitted, valve)
    leaves = ("Q_n", "u_curve", "flow_4", "flow_2")
    return with_updates(plant, {f"{valve}.{k}": getattr(v, k) for k in leaves})
