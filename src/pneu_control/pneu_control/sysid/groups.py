"""The per-segment check of a fit, and the global stage it starts: do the values explain every segment?

A fit of the whole record can settle where compensating errors explain most
of it while some segments are explained badly: on the motor, a centre and a
vane leakage both too high (+30 %, +110 %), the inertia, flow scale and
exhaust throttle a few per cent off and the unobservable exhaust volume at
its bound fit the turning segments as well as the truth does, but not the
ones with the valve held at 5 V (rest, coast-downs), where the leakages are
all that moves the gas: there the cost per segment is 20-40 times the
truth's (issue 21's wrong optimum).

So after the fit, each replayed segment's share of the cost is compared with
the median segment's: a segment above :data:`UNEXPLAINED` times it is not
explained by the fitted values (on a plant of the model's family, at the
right optimum, the largest is about 1.5 times the median: segments differ
by their start errors only). Those segments' design segments are then
fitted alone, every parameter from the fitted values -- the optimum of what
the fit explained worst -- and the whole fit runs again from there; the
lower cost of the two is kept. Whatever is still unexplained is reported
(:attr:`Check.unexplained`): a model that does not fit, or a minimum that
no start found.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from pneu_sim.physics import workers

__all__ = ["UNEXPLAINED", "Check", "check_segments", "refit_unexplained"]

UNEXPLAINED = 4.0  # a segment's cost above this many times the median segment's


@dataclass
class Check:
    """Per replayed segment: its record, design label and start (s), its cost; the median and
    the segments above :data:`UNEXPLAINED` times it."""

    costs: list[tuple[str, str, float, float]]  # (record, label, t0_s, cost)
    median: float
    unexplained: list[tuple[str, str, float, float]] = field(default_factory=list)

    def lines(self, axis: str) -> list[str]:
        """One line naming the unexplained segments (none if every segment is explained)."""
        if not self.unexplained:
            return []
        worst = sorted(self.unexplained, key=lambda c: -c[3])
        shown = "; ".join(
            f"{lab} at {t0:.1f} s ({c / self.median:.0f}x)" for _r, lab, t0, c in worst[:4]
        )
        more = f" and {len(worst) - 4} more" if len(worst) > 4 else ""
        return [
            f"{axis}: {len(worst)} segment(s) not explained by the identified values (cost "
            f"above {UNEXPLAINED:g}x the median segment's): {shown}{more}"
        ]


def check_segments(problem, z: np.ndarray) -> Check:
    """The per-segment costs of ``problem`` (:class:`pneu_control.sysid.fit.Problem`) at ``z``."""
    r = problem.residuals(z)
    cost = 0.5 * np.bincount(problem.cluster, r * r, problem.n_clusters)
    rows = []
    j = 0
    for rec, seg in problem.used:
        d = rec.designs.get(problem.axis)
        for s0 in seg.starts.tolist():
            t0 = s0 * rec.period_s
            label = d.segments[d.segment_at(t0 + 1e-9)].label if d is not None else f"{t0:.1f} s"
            rows.append((rec.path, label, t0, float(cost[j])))
            j += 1
    med = float(np.median(cost)) if len(cost) else 0.0
    bad = [c for c in rows if med > 0.0 and c[3] > UNEXPLAINED * med]
    return Check(rows, med, bad)


def refit_unexplained(
    axis: str, base, records, options, fit, check: Check, log: Callable[[str], None]
) -> dict[str, float] | None:
    """A start for the whole fit where the unexplained segments of ``check`` point: every
    parameter fitted on their design segments alone from ``fit``'s values and offsets; None
    when every segment is explained."""
    from pneu_control.sysid.fit import Problem

    if not check.unexplained:
        return None
    marks = {(rec, round(t0, 6)) for rec, _lab, t0, _c in check.unexplained}

    def select_for(rec):
        d = rec.designs.get(axis)
        starts = {round(t0, 6) for r, t0 in marks if r == rec.path}
        if d is None:
            return None
        chosen = {i for i, s in enumerate(d.segments) if any(s.t0_s <= t < s.t1_s for t in starts)}
        return lambda s: d.segments.index(s) in chosen

    picked = [(r, select_for(r)) for r in records]
    picked = [(r, sel) for r, sel in picked if sel is not None]
    if not picked:
        return None
    start = fit.start()
    opts = replace(options, params=tuple(fit.names))
    try:
        subs = [Problem(axis, base, [r], opts, select=sel, coarse=True) for r, sel in picked]
    except ValueError:
        return None
    # one problem over all the picked records: their residuals side by side
    sub = _Union(subs)
    z = sub.solve(start)
    vals, _ = subs[0].unpack(z)
    out = dict(zip(fit.names, vals))
    for p, o in zip(subs, sub.offsets(z)):
        out.update(p.offset_start(o))
    log(
        f"  {axis}: the unexplained segments alone: "
        + ", ".join(f"{n.split('.')[-1]}={v:.4g}" for n, v in zip(fit.names, vals))
    )
    return out


class _Union:
    """Several single-record problems with the same parameters as one least-squares problem."""

    def __init__(self, problems) -> None:
        self.problems = problems
        self.n_p = problems[0].n_p

    def _split(self, z: np.ndarray) -> list[np.ndarray]:
        out, k = [], self.n_p
        for p in self.problems:
            out.append(np.concatenate([z[: self.n_p], z[k : k + p.n_off]]))
            k += p.n_off
        return out

    def offsets(self, z: np.ndarray) -> list[list[dict[str, float]]]:
        return [p.unpack(zz)[1] for p, zz in zip(self.problems, self._split(z))]

    def solve(self, start: dict[str, float]) -> np.ndarray:
        from scipy.optimize import least_squares

        z0s = [p.z_start(start) for p in self.problems]
        z0 = np.concatenate([z0s[0][: self.n_p], *[z[self.n_p :] for z in z0s]])
        lo = np.concatenate(
            [self.problems[0].lo[: self.n_p], *[p.lo[self.n_p :] for p in self.problems]]
        )
        hi = np.concatenate(
            [self.problems[0].hi[: self.n_p], *[p.hi[self.n_p :] for p in self.problems]]
        )

        def res(z):
            return np.concatenate([p.residuals(zz) for p, zz in zip(self.problems, self._split(z))])

        opt = self.problems[0].options
        r = least_squares(res, np.clip(z0, lo, hi), bounds=(lo, hi), method="trf", diff_step=opt.diff_step, max_nfev=opt.max_nfev, xtol=opt.xtol, ftol=opt.ftol, workers=workers.map_tasks)  # fmt: skip
        return r.x
