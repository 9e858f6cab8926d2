"""Per-joint and path errors of a recorded two-axis run against its trajectory.

Per joint (DESIGN §7 sign: e = reference − measured), over the recorded samples:
e_max = max |e(t)|, RMSE = sqrt(mean e²), and the final error e(t_last), with
the reference of :func:`~pneu_control.controller.trajectory.joint_reference`
evaluated at each sample time.

Path error: the distance of each measured point (x, θ) to the intended x–θ
curve, the set of every (x_r(t), θ_r(t)) over the trajectory's whole time span.
The angle becomes a length through an equivalent radius r_eq (m per rad): the
point is (x, r_eq θ) and the curve a polyline through the references sampled at
every trajectory point and ``n_curve`` uniform times; the distance is to the
nearest segment (exact for the straight pieces every shipped shape has in the
x–θ plane: a screw is one line, insert-then-twist two). For a screw the
natural r_eq is p/(2π): r_eq θ is then the axial advance the angle asks for,
and the path error is an axial length ("mm equivalent"); :func:`screw` stores
it in the trajectory (``r_eq_m``), other shapes need it given (a tool radius,
say).

The path error is timing-free: it asks *where* the axes went, not *when*. A
run that follows the curve exactly but late (a lag along the path) has zero
path error and a per-joint error of about lag × speed; an offset across the
path (a screw thread that does not match the pitch) shows in both. Report both.

Everything is SI inside; :class:`PathReport` gives the path figures in mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pneu_msgs_py.contract.units import MM_PER_M
from pneu_msgs_py.params.core import ParamError

from pneu_control.controller.trajectory import JointTrajectory, joint_reference

__all__ = [
    "JointError",
    "PathReport",
    "analyse_path",
    "curve",
    "joint_errors",
    "path_distances",
]

_CHUNK = 32_768  # measured points × segments per block: temporaries of ~256 kB stay in cache


@dataclass(frozen=True)
class JointError:
    """One joint's error e = r − y over the samples: SI (m or rad)."""

    joint: str
    e_max: float
    rmse: float
    final: float


@dataclass(frozen=True)
class PathReport:
    """Per-joint errors (SI) and the path error in mm, with the r_eq that made it (NaN: no
    rotary joint)."""

    joints: dict[str, JointError]
    path_max_mm: float
    path_rms_mm: float
    r_eq_m: float
    n_samples: int

    def summary(self) -> str:
        """One line per joint (mm, deg) and one for the path."""
        lines = []
        for e in self.joints.values():
            k, u = (MM_PER_M, "mm") if e.joint == "linear" else (180.0 / math.pi, "deg")
            lines.append(
                f"{e.joint}: e_max {e.e_max * k:.4g} {u}, RMSE {e.rmse * k:.4g} {u}, "
                f"final {e.final * k:.4g} {u}"
            )
        scale = "" if math.isnan(self.r_eq_m) else f" (r_eq = {self.r_eq_m * MM_PER_M:.4g} mm/rad)"
        lines.append(
            f"path{scale}: max {self.path_max_mm:.4g} mm, "
            f"RMS {self.path_rms_mm:.4g} mm over {self.n_samples} samples"
        )
        return "\n".join(lines)


def _sample(traj: JointTrajectory, joint: str, t: np.ndarray) -> np.ndarray:
    ref = joint_reference(traj, joint)
    return np.array([ref(ti)[0] for ti in t.tolist()])


def _measured(traj: JointTrajectory, t, x, theta) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1 or t.size == 0:
        raise ParamError("t", t.shape, "a non-empty 1-D array of sample times (s)")
    given = {"linear": x, "rotary": theta}
    out = {}
    for name in traj.joint_names:
        if given[name] is None:
            arg = "x" if name == "linear" else "theta"
            raise ParamError(arg, None, f"measured {name} samples (the trajectory has that joint)")
        y = np.asarray(given[name], dtype=np.float64)
        if y.shape != t.shape:
            arg = "x" if name == "linear" else "theta"
            raise ParamError(arg, y.shape, f"the shape of t, {t.shape}")
        out[name] = y
    return t, out


def joint_errors(traj: JointTrajectory, t, x=None, theta=None) -> dict[str, JointError]:
    """e = r(t) − y(t) per joint at the sample times ``t`` (s): x in m, theta in rad."""
    t, ys = _measured(traj, t, x, theta)
    out = {}
    for name, y in ys.items():
        e = _sample(traj, name, t) - y
        out[name] = JointError(
            name, float(np.max(np.abs(e))), float(np.sqrt(np.mean(e * e))), float(e[-1])
        )
    return out


def _r_eq(traj: JointTrajectory, r_eq_m: float | None) -> float:
    r = traj.r_eq_m if r_eq_m is None else r_eq_m
    if "rotary" not in traj.joint_names:
        return math.nan if r is None else float(r)
    if r is None or not (isinstance(r, (int, float)) and math.isfinite(r) and r > 0.0):
        raise ParamError(
            "r_eq_m",
            r,
            "(0, inf) m per rad: the length one radian counts as (screw: pitch/(2π), set by screw())",
        )
    return float(r)


def curve(traj: JointTrajectory, r_eq_m: float | None = None, n_curve: int = 4000) -> np.ndarray:
    """The intended curve as polyline vertices, shape (N, n_joints): (x, r_eq θ) in m.

    Sampled at every trajectory point and ``n_curve`` uniform times over
    [t_start, t_end], sorted in time.
    """
    if not (isinstance(n_curve, int) and n_curve >= 2):
        raise ParamError("n_curve", n_curve, "an integer >= 2")
    r = _r_eq(traj, r_eq_m)
    t = np.union1d(np.asarray(traj.times), np.linspace(traj.t_start, traj.t_end, n_curve))
    cols = []
    for name in traj.joint_names:
        v = _sample(traj, name, t)
        cols.append(v if name == "linear" else r * v)
    return np.stack(cols, axis=1)


def _to_plane(traj: JointTrajectory, ys: dict[str, np.ndarray], r: float) -> np.ndarray:
    return np.stack([ys[n] if n == "linear" else r * ys[n] for n in traj.joint_names], axis=1)


def _distances(q: np.ndarray, verts: np.ndarray) -> np.ndarray:
    """Distance of each row of ``q`` (M, d) to the polyline ``verts`` (N, d), in blocks.

    Per segment a→b: u = clip((q − a)·(b − a)/|b − a|², 0, 1), distance |q − a − u (b − a)|.
    """
    a = verts[:-1] if len(verts) > 1 else verts
    d = verts[1:] - verts[:-1] if len(verts) > 1 else np.zeros_like(verts)
    l2 = np.sum(d * d, axis=1)
    inv = np.divide(1.0, l2, out=np.zeros_like(l2), where=l2 > 0.0)  # zero-length: the vertex
    out = np.empty(len(q))
    step = max(1, _CHUNK // len(a))
    for s in range(0, len(q), step):
        qa = [q[s : s + step, k, None] - a[None, :, k] for k in range(q.shape[1])]  # (m, n) each
        u = sum(c * d[None, :, k] for k, c in enumerate(qa)) * inv
        np.clip(u, 0.0, 1.0, out=u)
        e2 = sum((c - u * d[None, :, k]) ** 2 for k, c in enumerate(qa))
        out[s : s + step] = np.sqrt(np.min(e2, axis=1))
    return out


def path_distances(
    traj: JointTrajectory, x=None, theta=None, r_eq_m: float | None = None, n_curve: int = 4000
) -> np.ndarray:
    """Distance (m) of each measured point (x m, θ rad) to the intended x–θ curve."""
    ys = {"linear": x, "rotary": theta}
    n = None
    for name in traj.joint_names:
        if ys[name] is None:
            raise ParamError("x" if name == "linear" else "theta", None, f"measured {name} samples")
        ys[name] = np.asarray(ys[name], dtype=np.float64).ravel()
        if n is not None and ys[name].size != n:
            raise ParamError("theta", ys[name].size, f"as many samples as x ({n})")
        n = ys[name].size
    r = _r_eq(traj, r_eq_m)
    return _distances(_to_plane(traj, ys, r), curve(traj, r, n_curve))


def analyse_path(
    traj: JointTrajectory,
    t,
    x=None,
    theta=None,
    r_eq_m: float | None = None,
    n_curve: int = 4000,
) -> PathReport:
    """Per-joint errors and the path error of samples (t s, x m, θ rad) against ``traj``."""
    t, ys = _measured(traj, t, x, theta)
    r = _r_eq(traj, r_eq_m)
    dist = _distances(_to_plane(traj, ys, r), curve(traj, r, n_curve))
    return PathReport(
        joint_errors(traj, t, x, theta),
        float(np.max(dist)) * MM_PER_M,
        float(np.sqrt(np.mean(dist * dist))) * MM_PER_M,
        r,
        int(t.size),
    )
