"""The twin replayed on recorded valve voltages from a given state: noise-free, unquantised outputs.

System identification and validation (``pneu_control.sysid``) simulate the twin
on the voltages a bag says were on the valves, from a state built out of that
bag's measurements, and compare the outputs with the recorded sensors. They
need what the sensors *would* read without noise, offsets and AI/encoder
quantisation -- smooth in the parameters, so a finite-difference Jacobian
means something:

- the lagged pressures p_c1, p_c2, p_m1 and the lagged laser position x
  (the kernel's sensor lag states, Pa abs and m);
- the motor angle θ and the mean speed over each period, (θ_k − θ_{k−1})/T,
  which is what the encoder's Δcounts/T quantises (rad, rad/s).

The dynamics are the kernel's own ``substep`` (one copy of the physics); the
applied voltages go through the same AO clamp and quantisation
(:func:`pneu_sim.physics.kernel.ao_value`). The compiled functions inline the
kernel: their cache is dropped when it changes (:mod:`pneu_sim.physics.jit_cache`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numba import njit

from pneu_sim.physics import jit_cache, workers
from pneu_sim.physics import kernel as k
from pneu_sim.physics.pack import pack_params
from pneu_sim.physics.params import PlantParams

__all__ = [
    "R_PC1",
    "R_PC2",
    "R_PM1",
    "R_X",
    "R_TH",
    "R_OM",
    "N_REPLAY",
    "exhaust_pressure",
    "exhaust_pressures",
    "changed_openings",
    "mean_vane_factor",
    "opening_envelope",
    "replay",
    "replay_params",
    "replay_segments",
    "replay_state",
    "rod_torque",
    "spool_key",
    "spool_pass",
    "spool_trajectory",
]

R_PC1, R_PC2, R_PM1, R_X, R_TH, R_OM = range(6)
N_REPLAY = 6


AXES_CODE = {"both": 0, "linear": 1, "rotary": 2}


@njit(cache=True)
def _run(st, prm, u_l, u_r, i0, n, out, o0, which, p_c, feed, trace):
    """Periods i0 .. i0+n-1 of the voltages from ``st`` (in place) into rows o0 .. of ``out``;
    ``trace`` (unless empty): row o0 + j gets the state at the start of period i0 + j."""
    nsub = int(prm[k.P_NSUB])
    h = prm[k.P_H]
    T = prm[k.P_T]
    keep = trace.shape[0] > 0
    for j in range(n):
        i = i0 + j
        if keep:
            trace[o0 + j, :] = st
        if feed:  # the held cylinder's pressures, as recorded (the seal torque reads them)
            if math.isfinite(p_c[i, 0]) and math.isfinite(p_c[i, 1]):
                st[k.S_PC1] = p_c[i, 0]
                st[k.S_PC2] = p_c[i, 1]
        ul = k.ao_value(prm, u_l[i])
        ur = k.ao_value(prm, u_r[i])
        st[k.S_UL] = ul
        st[k.S_UR] = ur
        th0 = st[k.S_TH]
        K = k.vane_factor(prm, th0)
        for _ in range(nsub):
            if which != 2:
                k.substep_linear(st, prm, ul, h)
            if which != 1:
                K = k.substep_rotary(st, prm, ur, h, K)
            st[k.S_T] += h
        r = o0 + j
        out[r, 0] = st[k.S_FP1]
        out[r, 1] = st[k.S_FP2]
        out[r, 2] = st[k.S_FPM1]
        out[r, 3] = st[k.S_FX]
        out[r, 4] = st[k.S_TH]
        out[r, 5] = (st[k.S_TH] - th0) / T


@njit(cache=True, nogil=True)
def _replay(st, prm, u_l, u_r, out, which, p_c):
    feed = which == 2 and p_c.shape[0] == u_l.shape[0]
    _run(st, prm, u_l, u_r, 0, u_l.shape[0], out, 0, which, p_c, feed, np.zeros((0, k.N_STATE)))


@njit(cache=True, nogil=True)
def _replay_segments(states, prm, u_l, u_r, starts, lengths, rows, out, which, p_c, trace):
    feed = which == 2 and p_c.shape[0] == u_l.shape[0]
    for s in range(starts.shape[0]):  # the segments are independent (workers split them)
        st = states[s].copy()
        _run(st, prm, u_l, u_r, starts[s], lengths[s], out, rows[s], which, p_c, feed, trace)


@njit(cache=True)
def _spools(prm, base, u, out, env):
    st = np.zeros(k.N_STATE)
    u0 = k.ao_value(prm, u[0])
    st[k.S_SL] = u0
    st[k.S_YL] = u0
    nsub = int(prm[k.P_NSUB])
    for i in range(u.shape[0]):
        out[i, 0] = st[k.S_SL]
        out[i, 1] = st[k.S_SDL]
        out[i, 2] = st[k.S_YL]
        ui = k.ao_value(prm, u[i])
        lo, hi = math.inf, -math.inf
        for _ in range(nsub):
            y = k.spool_step(st, prm, base, k.S_SL, k.S_SDL, k.S_YL, ui)
            lo, hi = min(lo, y), max(hi, y)
        env[i, 0] = lo
        env[i, 1] = hi


def spool_trajectory(prm: np.ndarray, axis: str, u: np.ndarray) -> np.ndarray:
    """(n, 3): the valve spool (position, velocity, opening after the play) at the start of each
    period under the held voltages ``u`` -- the spool states at each sample, from rest at u[0].

    The spool depends on nothing the identification fits, so one pass over a
    record gives every segment its exact start (the play's state included).
    """
    return spool_pass(prm, axis, u)[0]


def opening_envelope(prm: np.ndarray, axis: str, u: np.ndarray) -> np.ndarray:
    """(n, 2): the least and greatest opening (V, after the play) the valve's flow curve is
    read at over the substeps of each period, under the held voltages ``u`` from rest at
    u[0] -- the same spool as :func:`spool_trajectory`, so every segment's replay reads
    its curve inside these bounds."""
    return spool_pass(prm, axis, u)[1]


def spool_pass(prm: np.ndarray, axis: str, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(:func:`spool_trajectory`, :func:`opening_envelope`) from one pass of the spool."""
    base = k.P_VALVE_L if axis == "linear" else k.P_VALVE_R
    uu = np.ascontiguousarray(u, dtype=np.float64)
    out, env = np.empty((uu.shape[0], 3)), np.empty((uu.shape[0], 2))
    _spools(prm, base, uu, out, env)
    return out, env


def changed_openings(prm0: np.ndarray, prm1: np.ndarray) -> tuple[str, float, float] | None:
    """Where two parameter vectors differ, if only in one valve's flow tables: (axis, lo, hi),
    the openings (V) whose flow reads a changed cell (:func:`pneu_sim.physics.kernel.port_flow`
    reads cells int(y/TAB_DU) and the next; a margin of a cell more each side; ±inf at
    the table's ends); ("linear", inf, -inf) when they do not differ; None when they
    differ anywhere else (every sample may change)."""
    diff = np.flatnonzero(prm0 != prm1)
    if not len(diff):
        return "linear", math.inf, -math.inf
    for axis, base in (("linear", k.P_VALVE_L), ("rotary", k.P_VALVE_R)):
        a, b = base + k.VB_TAB4, base + k.VB_SIZE
        if diff[0] >= a and diff[-1] < b:
            cells = (diff - a) % k.TAB_N
            c_lo, c_hi = int(cells.min()), int(cells.max())
            lo = (c_lo - 2) * k.TAB_DU if c_lo > 2 else -math.inf
            hi = (c_hi + 2) * k.TAB_DU if c_hi < k.TAB_N - 3 else math.inf
            return axis, lo, hi
    return None


def spool_key(prm: np.ndarray, axis: str) -> bytes:
    """Everything of ``prm`` :func:`spool_trajectory` reads for ``axis`` (the AO
    quantisation, the substeps, the spool's ZOH and play): equal keys, equal trajectories."""
    base = k.P_VALVE_L if axis == "linear" else k.P_VALVE_R
    idx = [k.P_AOR, k.P_AOLSB, k.P_AONMAX, k.P_NSUB, base + k.VB_HW]
    idx += list(range(base + k.VB_PHI11, base + k.VB_G2 + 1))
    return prm[idx].tobytes()


def replay_params(params: PlantParams) -> np.ndarray:
    """The kernel's parameter vector without sensor offsets (the replay has no noise)."""
    return pack_params(params, None)


def mean_vane_factor(prm: np.ndarray) -> float:
    """K̄: the sector mean of Eq. 8's factor (m³), torque per pressure difference."""
    th = np.linspace(0.0, 2.0 * math.pi / prm[k.P_NV], 65)
    return float(np.mean([k.vane_factor(prm, t) for t in th]))


def exhaust_pressure(prm: np.ndarray, p_m1: float, omega: float, kbar: float) -> float:
    """Quasi-steady motor exhaust pressure p_m2 (Pa abs): silencer flow = swept + leakage.

    p_m2 is not measured; its chamber is small and vents through the silencer
    in milliseconds, so the balance K̄·ω·p_m1/(R T0) + k_leak (p_m1 − p_m2) =
    ṁ_ex(p_m2 → p_a) (Eq. 11 through A_ex) sets it at a segment start.
    ``kbar``: :func:`mean_vane_factor`.
    """
    return float(_exhaust_pressure(prm, float(p_m1), float(omega), float(kbar)))


def exhaust_pressures(
    prm: np.ndarray, p_m1: np.ndarray, omega: np.ndarray, kbar: float
) -> np.ndarray:
    """:func:`exhaust_pressure` at each sample of the arrays ``p_m1`` (Pa abs) and ``omega``
    (rad/s), in one compiled call (same bits as the scalar one)."""
    p = np.ascontiguousarray(p_m1, dtype=np.float64)
    w = np.ascontiguousarray(omega, dtype=np.float64)
    out = np.empty(p.shape[0])
    _exhaust_pressures(prm, p, w, float(kbar), out)
    return out


@njit(cache=True)
def _exhaust_pressures(prm, p_m1, omega, kbar, out):
    for i in range(p_m1.shape[0]):
        out[i] = _exhaust_pressure(prm, p_m1[i], omega[i], kbar)


@njit(cache=True)
def _exhaust_pressure(prm, p_m1, omega, kbar):
    pa = prm[k.P_PA]
    RT = prm[k.P_RT]
    base = k.P_VALVE_R
    b, bl = prm[base + k.VB_B], prm[base + k.VB_BLAM]
    lo, hi = pa, max(pa, p_m1)
    if hi <= pa:
        return pa
    for _ in range(60):  # bisection
        mid = 0.5 * (lo + hi)
        inflow = kbar * max(omega, 0.0) * p_m1 / RT + prm[k.P_KLK] * (p_m1 - mid)
        out = k.iso_flow(mid, pa, prm[k.P_KEX], b, bl)[0]
        if inflow > out:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def replay_state(
    prm: np.ndarray,
    params: PlantParams,
    *,
    x: float,
    v: float,
    p_c1: float,
    p_c2: float,
    theta: float,
    omega: float,
    p_m1: float,
    u_linear: float,
    u_rotary: float,
    kbar: float | None = None,
    spool_linear: tuple[float, float, float] | None = None,
    spool_rotary: tuple[float, float, float] | None = None,
) -> np.ndarray:
    """A kernel state vector from measured values (SI, pressures absolute).

    Spools from ``spool_linear`` / ``spool_rotary`` (position, velocity,
    opening: :func:`spool_trajectory`) or else at rest at the voltages held
    during the previous period (the spool settles in a few ms); p_m2 quasi-steady (:func:`exhaust_pressure`;
    the paper's plumbing: in the bidirectional one p_m2 is neither measured nor quasi-steady);
    sensor lags at the measured values; gas masses p V / (R T0); the sleeve's torque
    from these (:func:`rod_torque`).
    """
    st = np.zeros(k.N_STATE)
    lin = params.linear
    half = 0.5 * lin.L
    x = min(max(x, -half), half)
    RT = prm[k.P_RT]
    st[k.S_X] = x
    st[k.S_V] = v
    st[k.S_PC1] = p_c1
    st[k.S_PC2] = p_c2
    st[k.S_TH] = theta
    st[k.S_OM] = omega
    st[k.S_PM1] = p_m1
    kbar = mean_vane_factor(prm) if kbar is None else kbar
    st[k.S_PM2] = exhaust_pressure(prm, p_m1, omega, kbar)
    for i_s, i_sd, i_y, u, sp in (
        (k.S_SL, k.S_SDL, k.S_YL, u_linear, spool_linear),
        (k.S_SR, k.S_SDR, k.S_YR, u_rotary, spool_rotary),
    ):
        if sp is None:
            uq = k.ao_value(prm, u)
            sp = (uq, 0.0, uq)
        st[i_s], st[i_sd], st[i_y] = sp
    st[k.S_UL] = st[k.S_SL]
    st[k.S_UR] = st[k.S_SR]
    st[k.S_MC1] = p_c1 * (lin.V_1d + lin.A_c1 * (half + x)) / RT
    st[k.S_MC2] = p_c2 * (lin.V_2d + lin.A_c2 * (half - x)) / RT
    st[k.S_FP1] = p_c1
    st[k.S_FP2] = p_c2
    st[k.S_FPM1] = p_m1
    st[k.S_FX] = x
    st[k.S_TROD] = rod_torque(prm, p_c1, p_c2, st[k.S_PM1], st[k.S_PM2], omega, kbar)
    return st


def rod_torque(
    prm: np.ndarray, p_c1: float, p_c2: float, p_m1: float, p_m2: float, omega: float, kbar: float
) -> float:
    """The torque the sleeve passes to the rod side (N·m), as the kernel's motor step sets it:
    turning, the seals' torque plus the load; at rest, at most what the motor applies."""
    pa = prm[k.P_PA]
    T_seal = prm[k.P_KSEAL] * (max(p_c1 - pa, 0.0) + max(p_c2 - pa, 0.0))
    if omega != 0.0:
        return T_seal + prm[k.P_TLC] + prm[k.P_CLD] * abs(omega)
    return min(abs(kbar * (p_m1 - p_m2)), T_seal + prm[k.P_TLS])


def _inputs(u_linear, u_rotary, axes: str, p_c):
    """The voltages and the recorded chamber pressures as contiguous arrays, checked."""
    u_l = np.ascontiguousarray(u_linear, dtype=np.float64)
    u_r = np.ascontiguousarray(u_rotary, dtype=np.float64)
    if u_l.shape != u_r.shape or u_l.ndim != 1:
        raise ValueError("u_linear and u_rotary must be 1-D arrays of equal length")
    if axes not in AXES_CODE:
        raise ValueError(f"axes: {axes!r} refused; allowed: one of {', '.join(AXES_CODE)}")
    pc = np.zeros((0, 2)) if p_c is None else np.ascontiguousarray(p_c, dtype=np.float64)
    if p_c is not None and (axes != "rotary" or pc.shape != (u_l.shape[0], 2)):
        raise ValueError("p_c: an (n, 2) array of chamber pressures, with axes='rotary' only")
    return u_l, u_r, pc


def replay(
    st: np.ndarray,
    prm: np.ndarray,
    u_linear: np.ndarray,
    u_rotary: np.ndarray,
    axes: str = "both",
    p_c: np.ndarray | None = None,
) -> np.ndarray:
    """Step ``st`` (in place) under the voltages held in each period; returns (n, 6) outputs.

    ``axes``: ``both``, or ``linear`` / ``rotary`` to step only that axis (the
    other's outputs then hold their start values; so does what couples the axes, the
    chamber pressures in the seal torque and the sleeve torque S_TROD: exact with
    ``coupling`` off, an approximation with it on). ``p_c``: with ``axes="rotary"``, the
    cylinder's chamber pressures (n, 2: p_c1, p_c2, Pa abs) at the start of each period,
    e.g. as recorded, for the seal torque instead of the held start values (a non-finite
    row keeps the previous values).

    Row i is the sample at the end of period i: columns :data:`R_PC1`,
    :data:`R_PC2`, :data:`R_PM1` (Pa abs), :data:`R_X` (m), :data:`R_TH`
    (rad), :data:`R_OM` (rad/s, mean over the period).
    """
    u_l, u_r, pc = _inputs(u_linear, u_rotary, axes, p_c)
    out = np.empty((u_l.shape[0], N_REPLAY))
    _replay(st, prm, u_l, u_r, out, AXES_CODE[axes], pc)
    return out


def replay_segments(
    states: np.ndarray,
    prm: np.ndarray,
    u_linear: np.ndarray,
    u_rotary: np.ndarray,
    starts: np.ndarray,
    lengths: np.ndarray,
    axes: str = "both",
    p_c: np.ndarray | None = None,
    trace: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`replay` of many segments at once, in parallel (split over the replay's worker
    threads, :mod:`pneu_sim.physics.workers`; each segment's arithmetic is :func:`replay`'s,
    so the rows are the same bits).

    Segment s starts from ``states[s]`` (not modified) at period ``starts[s]`` of the
    full-record voltages ``u_linear``/``u_rotary`` and runs ``lengths[s]`` periods;
    ``p_c``: the full record's chamber pressures (as in :func:`replay`, ``axes="rotary"``
    only). Returns the segments' rows one after the other: (Σ lengths, 6). ``trace``: a
    (Σ lengths, N_STATE) array that gets, row for row, the state each period starts from
    (a segment restarted from its row j replays rows j... to the same bits).
    """
    u_l, u_r, pc = _inputs(u_linear, u_rotary, axes, p_c)
    st = np.ascontiguousarray(states, dtype=np.float64).reshape(-1, k.N_STATE)
    i0 = np.ascontiguousarray(starts, dtype=np.int64)
    n = np.ascontiguousarray(lengths, dtype=np.int64)
    if not (st.shape[0] == i0.shape[0] == n.shape[0]) or (
        len(n) and (i0.min() < 0 or n.min() < 0 or (i0 + n).max() > u_l.shape[0])
    ):
        raise ValueError("states, starts, lengths: one per segment, inside the voltages")
    rows = np.concatenate(([0], np.cumsum(n)[:-1])).astype(np.int64) if len(n) else n
    out = np.empty((int(n.sum()), N_REPLAY))
    tr = np.zeros((0, k.N_STATE)) if trace is None else trace
    if tr.shape[0] and tr.shape != (out.shape[0], k.N_STATE):
        raise ValueError(f"trace: shape {tr.shape} refused; allowed: ({out.shape[0]}, {k.N_STATE})")
    which = AXES_CODE[axes]

    def chunk(c: np.ndarray) -> None:
        _replay_segments(st[c], prm, u_l, u_r, i0[c], n[c], rows[c], out, which, pc, tr)

    workers.run_all([lambda c=c: chunk(c) for c in _chunks(n, workers.size())])
    return out


# periods: a smaller chunk is not worth a hand-over (estimated: handing a task to a thread
# costs tens of µs, 2000 periods of replay about a millisecond)
_MIN_CHUNK = 2000


def _chunks(lengths: np.ndarray, n_max: int) -> list[np.ndarray]:
    """The segments' indices in at most ``n_max`` chunks of nearly equal periods (longest
    first, each to the lightest chunk), each in ascending order."""
    m = int(min(n_max, max(1, lengths.sum() // _MIN_CHUNK), len(lengths)))
    if m <= 1:
        return [np.arange(len(lengths))]
    load = np.zeros(m)
    owner = np.empty(len(lengths), dtype=np.int64)
    for i in np.argsort(-lengths, kind="stable").tolist():
        j = int(np.argmin(load))
        owner[i] = j
        load[j] += lengths[i]
    return [np.flatnonzero(owner == j) for j in range(m)]


# the compiled functions above inline the kernel (another file): keep their caches in step
for _name, _fn in (
    ("_run", _run),
    ("_replay", _replay),
    ("_replay_segments", _replay_segments),
    ("_spools", _spools),
    ("_exhaust_pressure", _exhaust_pressure),
):
    jit_cache.refresh_cache(_fn, (Path(__file__), Path(k.__file__)), f"replay.{_name}")
