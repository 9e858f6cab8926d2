"""Paper-style figures (Fig. 11–14): reference vs measured, error, valve voltage.

Input is plain per-run series (SI); the axes are labelled in report units.
matplotlib is imported lazily with the Agg backend (no display needed).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pneu_msgs_py.contract.units import MM_PER_M, RPM_PER_RAD_S

__all__ = ["FORMATS", "Series", "plot_runs", "pyplot"]

_SCALE = {"linear": (MM_PER_M, "mm", "displacement"), "rotary": (RPM_PER_RAD_S, "rpm", "speed")}


@dataclass
class Series:
    """One axis of one run, SI arrays on the sample grid."""

    label: str
    axis: str
    t: np.ndarray
    reference: np.ndarray
    measured: np.ndarray
    u: np.ndarray
    pressures: dict[str, np.ndarray] | None = None  # name -> Pa abs
    window_s: tuple[float, float] | None = None


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend (imported when a figure is drawn)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


FORMATS = (".png", ".pdf", ".svg")


def plot_runs(
    series: list[Series],
    title: str,
    path: str | Path,
    *,
    pressures: bool = False,
    fmt: str | None = None,
) -> Path:
    """One figure: a column per run with reference/measured, error, valve voltage rows.

    ``fmt`` (``png``, ``pdf``, ``svg``; default: from ``path``'s suffix) lets the
    figure be written under a temporary name.
    """
    plt = pyplot()
    n = len(series)
    rows = 4 if pressures else 3
    fig, axs = plt.subplots(rows, n, figsize=(4.2 * n, 2.3 * rows), sharex="col", squeeze=False)
    for j, s in enumerate(series):
        scale, unit, what = _SCALE[s.axis]
        ax = axs[0][j]
        ax.plot(s.t, s.reference * scale, "k--", lw=1.0, label="reference")
        ax.plot(s.t, s.measured * scale, "C0", lw=0.8, label="measured")
        ax.set_title(s.label, fontsize=9)
        ax.set_ylabel(f"{what} ({unit})")
        ax.legend(fontsize=7, loc="best")
        ax = axs[1][j]
        ax.plot(s.t, (s.reference - s.measured) * scale, "C3", lw=0.6)
        if s.window_s is not None:
            ax.axvspan(s.window_s[0], s.window_s[1], color="0.9", zorder=0, label="steady window")
            ax.legend(fontsize=7, loc="upper right")
        ax.set_ylabel(f"error ({unit})")
        ax = axs[2][j]
        ax.plot(s.t, s.u, "C2", lw=0.6)
        ax.axhline(5.0, color="0.6", lw=0.5)
        ax.set_ylabel("valve (V)")
        if pressures:
            ax = axs[3][j]
            for name, p in (s.pressures or {}).items():
                ax.plot(s.t, p * 1e-6, lw=0.7, label=name)
            ax.set_ylabel("p (MPa abs)")
            ax.legend(fontsize=7)
        axs[rows - 1][j].set_xlabel("t (s)")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, format=fmt or (out.suffix.lstrip(".") or "png"))
    plt.close(fig)
    return out
