"""Replay a record through the twin in segments started from the measured state (multiple shooting).

The cylinder is an integrator: a whole bag replayed open loop on its recorded
voltages drifts away on any parameter error, and the fit would see the drift,
not the physics. So the record is cut into segments of at most
``segment_s``; each starts from the state the sensors give at its first
sample (position and velocity from a local line through the laser samples,
the pressures as a centred mean less their offsets, the encoder angle and
the mean encoder speed around it, the motor exhaust pressure quasi-steady,
the valve spools from one pass of the spool model over the recorded
voltages) and runs open loop on the recorded voltages
(:func:`pneu_sim.physics.replay.replay_segments`: every segment at once, in parallel). With an excitation design the cuts
fall on its segment boundaries (the rig is at its calmest there: a pulse
starts from rest and is replayed whole). ``segment_s`` = ∞ is a pure
simulation from the first sample (MATLAB ``compare``'s default).

A replay can be kept whole (:func:`trace`: the state each period starts from),
and a replay with other values started again from it where they cannot have
acted yet (:func:`simulate_from`, the same bits): what the fit's Jacobian uses
for a valve's curve knots, which act only once the spool opens that far.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from pneu_sim.physics import replay as rp

from pneu_control.sysid.record import AXIS_SIGNALS, SIGNALS, Record

__all__ = [
    "Segments",
    "Trace",
    "initial_states",
    "segments_of",
    "simulate",
    "simulate_from",
    "trace",
]

_COL = {"p_c1": rp.R_PC1, "p_c2": rp.R_PC2, "p_m1": rp.R_PM1, "x": rp.R_X, "theta": rp.R_TH, "omega": rp.R_OM}  # fmt: skip
_X_FIT = 10  # samples either side for the position/velocity line at a segment start
_W_AVG = 5  # samples either side for the mean encoder speed
_P_AVG = 5  # samples either side for the pressures (a centred mean is unbiased on a ramp)


@dataclass
class Segments:
    """Segments of one record: start sample indices and lengths (samples simulated)."""

    starts: np.ndarray
    lengths: np.ndarray

    @property
    def index(self) -> np.ndarray:
        """Concatenated indices of the simulated samples (start + 1 ... start + length, per segment)."""
        if not len(self.starts):
            return np.zeros(0, dtype=np.int64)
        return np.concatenate(
            [np.arange(s + 1, s + 1 + n) for s, n in zip(self.starts, self.lengths)]
        )

    def __len__(self) -> int:
        return len(self.starts)


def _cuts(rec: Record, axis: str, segment_s: float) -> list[tuple[int, int]]:
    """(start, length) pieces of at most ``segment_s``, on the design's boundaries if any."""
    n = rec.n
    first, last = _X_FIT, n - _X_FIT - 2
    if math.isinf(segment_s):
        return [(first, last - first)]
    L = max(2, int(round(segment_s / rec.period_s)))
    d = rec.designs.get(axis)
    if d is None:
        bounds = [*list(range(first, last, L)), last]
    else:
        marks = [int(round(s.t0_s / rec.period_s)) for s in d.segments] + [last]
        bounds = []
        for a, b in itertools.pairwise(marks):
            a, b = max(a, first), min(b, last)
            if b <= a:
                continue
            k = max(1, math.ceil((b - a) / L))
            bounds.extend(a + (b - a) * i // k for i in range(k))
        bounds.append(last)
    return [(a, b - a) for a, b in itertools.pairwise(bounds) if b - a >= 2]


def segments_of(rec: Record, axis: str, segment_s: float) -> Segments:
    """Segments of at most ``segment_s`` fully inside ``rec.valid[axis]``, with every compared
    sample finite; ``segment_s`` = ∞: one from the first sample of each stretch of such data
    (the whole record when all of it is valid)."""
    ok = rec.valid[axis].copy()
    for name in AXIS_SIGNALS[axis]:
        ok &= np.isfinite(rec.y[name])
    if math.isinf(segment_s):
        return _stretches(ok)
    bad = np.concatenate(([0], np.cumsum(~ok)))
    keep = [
        (s, n)
        for s, n in _cuts(rec, axis, segment_s)
        if bad[s + n + 1] - bad[max(s - _X_FIT, 0)] == 0
    ]
    return Segments(
        np.array([s for s, _ in keep], dtype=np.int64),
        np.array([n for _, n in keep], dtype=np.int64),
    )


def _stretches(ok: np.ndarray) -> Segments:
    """One segment per run of ``ok`` samples: from _X_FIT samples into it (the start's line
    fit) to its end, inside the record's margins; at least two samples."""
    n = len(ok)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], ok.astype(np.int8), [0]))))
    starts, lengths = [], []
    for a, b in zip(edges[::2].tolist(), edges[1::2].tolist()):  # run [a, b)
        s = max(a + _X_FIT, _X_FIT)
        e = min(b - 1, n - _X_FIT - 2)  # the last simulated sample is s + length
        if e - s >= 2:
            starts.append(s)
            lengths.append(e - s)
    return Segments(np.array(starts, dtype=np.int64), np.array(lengths, dtype=np.int64))


def _line(t: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Value at t = 0 and slope of the least-squares line through (t, y), NaNs dropped."""
    m = np.isfinite(y)
    if m.sum() < 2:
        return (float(np.mean(y[m])) if m.any() else 0.0), 0.0
    tt, yy = t[m], y[m]
    a = np.polyfit(tt, yy, 1)
    return float(a[1]), float(a[0])


def _mean(v: np.ndarray, default: float) -> float:
    m = np.isfinite(v)
    return float(np.mean(v[m])) if m.any() else default


def _measured_starts(rec: Record, seg: Segments) -> list[dict]:
    """The sensors' state at each segment start, before any offset is taken off (computed once
    per record and segmentation: it depends on nothing the fit moves)."""
    key = ("starts", seg.starts.tobytes())
    if key in rec.memo:
        return rec.memo[key]
    T = rec.period_s
    tw = np.arange(-_X_FIT, _X_FIT + 1) * T
    out = []
    y = rec.y
    for i0 in seg.starts.tolist():
        x0, v0 = _line(tw, y["x"][i0 - _X_FIT : i0 + _X_FIT + 1])
        om0 = _mean(y["omega"][max(i0 - _W_AVG + 1, 0) : i0 + _W_AVG + 1], 0.0)
        th0 = y["theta"][i0]
        pw = slice(i0 - _P_AVG, i0 + _P_AVG + 1)
        out.append(
            {
                "x": x0 if math.isfinite(x0) else 0.0,
                "v": v0 if math.isfinite(v0) else 0.0,
                "p_c1": _mean(y["p_c1"][pw], 2e5),
                "p_c2": _mean(y["p_c2"][pw], 2e5),
                "p_m1": _mean(y["p_m1"][pw], 1.01325e5),
                "theta": float(th0) if math.isfinite(th0) else 0.0,
                "omega": om0,
                "u_linear": float(rec.u["linear"][i0 - 1]),
                "u_rotary": float(rec.u["rotary"][i0 - 1]),
            }
        )
    rec.memo[key] = out
    return out


def initial_states(
    rec: Record, seg: Segments, offsets: dict[str, float], spools: dict[str, np.ndarray]
) -> list[dict]:
    """Measured state at each segment start (see the module docstring)."""
    out = []
    for i0, m in zip(seg.starts.tolist(), _measured_starts(rec, seg)):
        s0 = dict(m)
        for name in ("p_c1", "p_c2", "p_m1"):
            s0[name] = m[name] - offsets.get(name, 0.0)
        s0["spool_linear"] = tuple(spools["linear"][i0])
        s0["spool_rotary"] = tuple(spools["rotary"][i0])
        out.append(s0)
    return out


def _spool_pass(rec: Record, prm: np.ndarray, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pneu_sim.physics.replay.spool_pass` over the record (the spool's states at each
    sample, its opening's bounds in each period), once per spool model."""
    key = ("spools", axis, rp.spool_key(prm, axis))
    if key not in rec.memo:
        rec.memo[key] = rp.spool_pass(prm, axis, rec.u[axis])
    return rec.memo[key]


@dataclass
class Trace:
    """One replay of a record's segments kept whole (:func:`trace`): what a replay with other
    values starts again from, where those values cannot have acted yet (:func:`simulate_from`)."""

    rec: Record
    seg: Segments
    axes: str
    prm: np.ndarray
    states: np.ndarray  # (segments, N_STATE): each segment's start
    sim: np.ndarray  # (Σ lengths, N_REPLAY): the replayed rows
    period_states: np.ndarray  # (Σ lengths, N_STATE): the state each row's period starts from
    rows: np.ndarray  # first row of each segment
    offsets: dict[str, float]  # the sensor offsets the start states were built with
    p_c: np.ndarray | None  # the recorded cylinder pressures fed to a rotary replay


def _setup(params, rec: Record, seg: Segments, offsets: dict[str, float], axes: str):
    """(prm, segment start states, the recorded cylinder pressures for a rotary replay)."""
    prm = rp.replay_params(params)
    return (prm, *_starts(prm, params, rec, seg, offsets, axes))


def _starts(prm, params, rec: Record, seg: Segments, offsets: dict[str, float], axes: str):
    """(segment start states, the recorded cylinder pressures for a rotary replay)."""
    kbar = rp.mean_vane_factor(prm)
    spools = {a: _spool_pass(rec, prm, a)[0] for a in ("linear", "rotary")}
    states = initial_states(rec, seg, offsets, spools)
    p_c = None
    if axes == "rotary":  # the seal torque reads the cylinder's pressures: feed the recorded ones
        p_c = np.column_stack([rec.y[c] - offsets.get(c, 0.0) for c in ("p_c1", "p_c2")])
    st = np.array([rp.replay_state(prm, params, kbar=kbar, **s0) for s0 in states])
    return st.reshape(len(seg), -1), p_c


def _outputs(sim: np.ndarray, offsets: dict[str, float]) -> dict[str, np.ndarray]:
    out = {name: sim[:, _COL[name]] for name in SIGNALS}
    for name, off in offsets.items():
        out[name] = out[name] + off
    return out


def simulate(
    params, rec: Record, seg: Segments, offsets: dict[str, float], axes: str = "both"
) -> dict[str, np.ndarray]:
    """Replay every segment (``axes``: both, linear or rotary); returns SIGNALS -> simulated
    sensor values at :attr:`Segments.index` (pressures with ``offsets`` added back, as the
    sensors read them)."""
    prm, st, p_c = _setup(params, rec, seg, offsets, axes)
    sim = rp.replay_segments(
        st, prm, rec.u["linear"], rec.u["rotary"], seg.starts, seg.lengths, axes, p_c
    )
    return _outputs(sim, offsets)


def trace(
    params, rec: Record, seg: Segments, offsets: dict[str, float], axes: str = "both"
) -> tuple[dict[str, np.ndarray], Trace]:
    """:func:`simulate`, and the replay kept whole (the same bits)."""
    prm, st, p_c = _setup(params, rec, seg, offsets, axes)
    n = int(seg.lengths.sum())
    kept = np.empty((n, st.shape[1]))
    sim = rp.replay_segments(
        st, prm, rec.u["linear"], rec.u["rotary"], seg.starts, seg.lengths, axes, p_c, kept
    )
    rows = np.concatenate(([0], np.cumsum(seg.lengths)[:-1])).astype(np.int64)
    return _outputs(sim, offsets), Trace(
        rec, seg, axes, prm, st, sim, kept, rows, dict(offsets), p_c
    )


def simulate_from(params, base: Trace, offsets: dict[str, float]) -> dict[str, np.ndarray]:
    """:func:`simulate` with other values, to the same bits, replaying each segment only from
    the first period the change can act in: a change confined to a valve's flow curve acts
    from the first period whose spool opening reads a changed cell of it (the spool depends
    on nothing fitted); a segment whose start state changed, or any other change, replays
    whole. The rows before are ``base``'s."""
    rec, seg = base.rec, base.seg
    prm = rp.replay_params(params)
    where = rp.changed_openings(base.prm, prm)
    if where is not None and offsets == base.offsets:
        st, p_c = base.states, base.p_c  # a start state reads nothing of the flow tables
    else:
        st, p_c = _starts(prm, params, rec, seg, offsets, base.axes)
    n = seg.lengths
    first = np.zeros(len(seg), dtype=np.int64)
    if where is not None:
        axis, lo, hi = where
        env = _spool_pass(rec, prm, axis)[1]
        hit = (env[:, 1] >= lo) & (env[:, 0] <= hi)
        for s, (i0, ns) in enumerate(zip(seg.starts.tolist(), n.tolist())):
            h = np.flatnonzero(hit[i0 : i0 + ns])
            first[s] = h[0] if len(h) else ns
    first[np.any(st != base.states, axis=1)] = 0
    go = first < n
    sim = base.sim.copy()
    if go.any():
        r0 = base.rows[go] + first[go]
        start = np.where(first[go][:, None] == 0, st[go], base.period_states[r0])
        part = rp.replay_segments(
            start, prm, rec.u["linear"], rec.u["rotary"], seg.starts[go] + first[go],
            n[go] - first[go], base.axes, p_c,
        )  # fmt: skip
        idx = np.concatenate([np.arange(a, a + m) for a, m in zip(r0, n[go] - first[go])])
        sim[idx] = part
    return _outputs(sim, offsets)
