"""``pneu sim``: open-loop run of the twin at constant valve voltages.

Writes ``sim.csv`` (SI columns: the sensor sample of every tick plus the true x and ω)
and ``sim.png`` (displacement, speed, pressures), and prints the end position (mm)
and the steady speed (rpm).
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from pathlib import Path

from pneu_msgs_py.contract.units import RPM_PER_RAD_S

from pneu_sim.cli import live_options

NAME = "sim"
HELP = "run the plant twin open loop at constant valve voltages; write CSV + PNG"

__all__ = ["NAME", "HELP", "add_arguments", "run", "simulate"]

CSV_COLUMNS = (
    "t_s",
    "u_linear_V",
    "u_rotary_V",
    "p_c1_Pa",
    "p_c2_Pa",
    "p_m1_Pa",
    "x_m",
    "theta_rad",
    "omega_rad_s",
    "counts",
    "x_true_m",
    "omega_true_rad_s",
)


def _voltage(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (0.0 <= v <= 10.0):
        raise argparse.ArgumentTypeError(f"{v:g} V outside the valve range [0, 10] V")
    return v


def _duration(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (0.0 < v <= 3600.0):
        raise argparse.ArgumentTypeError(f"{v:g} s outside (0, 3600] s")
    return v


def _seed(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"{v} < 0")
    return v


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=_duration, default=5.0, help="simulated time, s (default 5)")
    p.add_argument(
        "--linear-voltage",
        type=_voltage,
        default=5.0,
        help="linear valve command, V (0-10, 5 = closed centre)",
    )
    p.add_argument(
        "--rotary-voltage", type=_voltage, default=5.0, help="rotary valve command, V (0-10)"
    )
    p.add_argument("--out", type=Path, required=True, help="output directory (created)")
    p.add_argument("--seed", type=_seed, default=0, help="noise seed (default 0)")
    p.add_argument(
        "--plant", type=Path, default=None, help="plant YAML (default config/plant.yaml)"
    )
    p.add_argument("--no-plot", action="store_true", help="skip the PNG")
    live_options.add_arguments(p)


def simulate(
    params,
    duration_s: float,
    u_linear: float,
    u_rotary: float,
    seed: int = 0,
    progress=None,
    live=None,
):
    """Run open loop; returns a list of CSV rows (tuples in CSV_COLUMNS order).

    ``live``: a :class:`pneu_msgs_py.live.server.LiveServer` that gets every sample and
    the (constant) valve commands.
    """
    from pneu_sim.physics.plant import Plant

    plant = Plant(params, seed=seed)
    n = round(duration_s / plant.T)
    s = plant.reset()
    st = plant.state

    def publish(s) -> None:
        live.write_cycle(s, ())
        live.write_command("linear", s.stamp_ns, u_linear)
        live.write_command("rotary", s.stamp_ns, u_rotary)

    if live is not None:
        publish(s)
    rows = [
        (
            0.0,
            u_linear,
            u_rotary,
            s.p_c1,
            s.p_c2,
            s.p_m1,
            s.x,
            s.theta,
            s.omega,
            s.counts,
            st.x,
            st.omega,
        )
    ]
    t_wall = time.perf_counter()
    t_last = t_wall
    for i in range(n):
        s = plant.step(u_linear, u_rotary)
        st = plant.state
        if live is not None:
            publish(s)
        rows.append(
            (
                s.stamp_ns * 1e-9,
                u_linear,
                u_rotary,
                s.p_c1,
                s.p_c2,
                s.p_m1,
                s.x,
                s.theta,
                s.omega,
                s.counts,
                st.x,
                st.omega,
            )
        )
        if progress is not None and (i & 1023) == 0:
            now = time.perf_counter()
            if now - t_last > 2.0:
                progress(i + 1, n)
                t_last = now
    return rows


def _plot(rows, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = [r[0] for r in rows]
    fig, ax = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    ax[0].plot(t, [r[6] * 1e3 for r in rows], label="laser x")
    ax[0].plot(t, [r[10] * 1e3 for r in rows], "--", label="true x")
    ax[0].set_ylabel("displacement (mm)")
    ax[0].legend(loc="best")
    ax[1].plot(t, [r[8] * RPM_PER_RAD_S for r in rows], label="encoder ω (Δcounts / T)")
    ax[1].plot(t, [r[11] * RPM_PER_RAD_S for r in rows], "--", label="true ω")
    ax[1].set_ylabel("speed (rpm)")
    ax[1].legend(loc="best")
    for col, lab in ((3, "p_c1"), (4, "p_c2"), (5, "p_m1")):
        ax[2].plot(t, [r[col] * 1e-5 for r in rows], label=lab)
    ax[2].set_ylabel("pressure (bar abs)")
    ax[2].set_xlabel("time (s)")
    ax[2].legend(loc="best")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    from pneu_sim.physics.plant_file import load_plant

    params = load_plant(args.plant)  # ParamError (a ValueError) -> one line via the dispatcher
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)

    def progress(i: int, n: int) -> None:
        print(f"pneu sim: {i}/{n} steps ({100.0 * i / n:.0f} %)", file=sys.stderr, flush=True)

    live = live_options.open_live(
        args, axes=("linear", "rotary"), kind="both", controller_state=False
    )
    try:
        rows = simulate(
            params,
            args.duration,
            args.linear_voltage,
            args.rotary_voltage,
            args.seed,
            progress,
            live=live,
        )
    finally:
        if live is not None:
            live.close()
    csv_path = out / "sim.csv"
    with open(csv_path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_COLUMNS)
        w.writerows(rows)
    T = params.sim.T
    n_end = max(1, round(0.1 / T))  # end position: last 100 ms of laser samples
    x_end_mm = 1e3 * sum(r[6] for r in rows[-n_end:]) / len(rows[-n_end:])
    n_ss = max(1, min(len(rows) - 1, round(1.0 / T)))  # steady speed: last 1 s of encoder speed
    w_ss = sum(r[8] for r in rows[-n_ss:]) / n_ss
    print(f"end position: {x_end_mm:.2f} mm (laser, mean of the last {n_end * T * 1e3:.0f} ms)")
    print(
        f"steady speed: {w_ss * RPM_PER_RAD_S:.1f} rpm (encoder, mean of the last {n_ss * T:.2f} s)"
    )
    print(f"wrote {csv_path}")
    if not args.no_plot:
        png = out / "sim.png"
        title = f"pneu sim: u_linear {args.linear_voltage:g} V, u_rotary {args.rotary_voltage:g} V, seed {args.seed}"
        _plot(rows, png, title)
        print(f"wrote {png}")
    if not math.isfinite(x_end_mm):
        return 1
    return 0
