"""``pneu sim``: open-loop run of the twin at constant valve voltages.

Writes ``sim.csv`` (SI columns: the sensor sample of every tick plus the true x and ω)
and ``sim.png`` (displacement, speed, pressures), and prints the end position (mm)
and the steady speed (rpm). Interrupted (SIGINT, SIGTERM, SIGHUP), both hold what ran
and say so: the CSV's last line is ``# interrupted by SIGINT at 4.000 s of 600 s: ...``
(a comment line), the figure's title too.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from pathlib import Path

import numpy as np
from pneu_msgs_py.contract.units import RPM_PER_RAD_S
from pneu_msgs_py.lifecycle import exits, signals
from pneu_msgs_py.lifecycle.duration import check_duration
from pneu_msgs_py.lifecycle.outputs import OutputDir
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.spec import parse_number
from pneu_msgs_py.params.yaml_file import from_option

from pneu_sim.cli import live_options

NAME = "sim"
HELP = "run the plant twin open loop at constant valve voltages; write CSV + PNG"

__all__ = ["NAME", "HELP", "add_arguments", "run", "simulate"]

ARTEFACTS = ("sim.csv", "sim.png")

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
        v = parse_number(text, float)  # as typed: 0_5 is not 5
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    if not (0.0 <= v <= 10.0):  # NaN fails too
        raise argparse.ArgumentTypeError(f"{v:g} V outside the valve range [0, 10] V")
    return v


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--duration",
        type=float,
        default=5.0,
        help="simulated time, s, [0.01, 600] (the duration cap of every command; default 5)",
    )
    p.add_argument(
        "--linear-voltage",
        type=_voltage,
        default=5.0,
        help="linear valve command, V (0-10, 5 = closed centre)",
    )
    p.add_argument(
        "--rotary-voltage", type=_voltage, default=5.0, help="rotary valve command, V (0-10)"
    )
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        help="output directory: new or empty (or --overwrite); gets sim.csv, sim.png",
    )
    p.add_argument(
        "--overwrite", action="store_true", help="replace sim.csv and sim.png in the directory"
    )
    p.add_argument("--seed", type=int, default=0, help="noise seed, an integer in [0, 2^32 - 1]")
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
) -> np.ndarray:
    """Run open loop; rows in CSV_COLUMNS order, an array preallocated for the whole run.

    A signal recorded by :mod:`pneu_msgs_py.lifecycle.signals` (under
    ``signals.deferred()``) stops at the next step: the rows that ran are returned.
    ``live``: a :class:`pneu_msgs_py.live.server.LiveServer` that gets every sample and
    the (constant) valve commands.
    """
    from pneu_sim.physics.plant import Plant

    sig = signals.STATE
    plant = Plant(params, seed=seed)
    n = round(duration_s / plant.T)
    rows = np.empty((n + 1, len(CSV_COLUMNS)))
    s = plant.reset()
    st = plant.state

    def publish(s) -> None:
        live.write_cycle(s, ())
        live.write_command("linear", s.stamp_ns, u_linear)
        live.write_command("rotary", s.stamp_ns, u_rotary)

    if live is not None:
        publish(s)
    rows[0] = (0.0, u_linear, u_rotary, s.p_c1, s.p_c2, s.p_m1, s.x, s.theta, s.omega, s.counts,
               st.x, st.omega)  # fmt: skip
    t_wall = time.perf_counter()
    t_last = t_wall
    m = 1
    for i in range(n):
        if sig.pending is not None:
            break
        s = plant.step(u_linear, u_rotary)
        st = plant.state
        if live is not None:
            publish(s)
        rows[i + 1] = (s.stamp_ns * 1e-9, u_linear, u_rotary, s.p_c1, s.p_c2, s.p_m1, s.x,
                       s.theta, s.omega, s.counts, st.x, st.omega)  # fmt: skip
        m = i + 2
        if progress is not None and (i & 1023) == 0:
            now = time.perf_counter()
            if now - t_last > 2.0:
                progress(i + 1, n)
                t_last = now
    return rows[:m]


def _write_csv(path: Path, rows, marker: str) -> None:
    """``rows`` as CSV; ``marker`` (an interruption) as the last line, a ``#`` comment
    (numpy's loadtxt and pandas' ``comment="#"`` skip it)."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_COLUMNS)
        w.writerows([*r[:9].tolist(), int(r[9]), *r[10:].tolist()] for r in rows)
        if marker:
            fh.write(f"# {marker}: the rows above are what ran\n")


def _plot(rows, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = rows[:, 0]
    fig, ax = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    ax[0].plot(t, rows[:, 6] * 1e3, label="laser x")
    ax[0].plot(t, rows[:, 10] * 1e3, "--", label="true x")
    ax[0].set_ylabel("displacement (mm)")
    ax[0].legend(loc="best")
    ax[1].plot(t, rows[:, 8] * RPM_PER_RAD_S, label="encoder ω (Δcounts / T)")
    ax[1].plot(t, rows[:, 11] * RPM_PER_RAD_S, "--", label="true ω")
    ax[1].set_ylabel("speed (rpm)")
    ax[1].legend(loc="best")
    for col, lab in ((3, "p_c1"), (4, "p_c2"), (5, "p_m1")):
        ax[2].plot(t, rows[:, col] * 1e-5, label=lab)
    ax[2].set_ylabel("pressure (bar abs)")
    ax[2].set_xlabel("time (s)")
    ax[2].legend(loc="best")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    from pneu_sim.physics.plant_file import load_plant

    # everything checked before anything is written
    duration = check_duration(args.duration)
    if not 0 <= args.seed <= 2**32 - 1:
        raise ParamError("--seed", args.seed, f"an integer in [0, {2**32 - 1}]")
    claim = OutputDir(args.out, ARTEFACTS, overwrite=args.overwrite, inputs=[args.plant]).check()
    with from_option("--plant" if args.plant else None):
        params = load_plant(args.plant)  # ParamError -> one line, exit 2

    def progress(i: int, n: int) -> None:
        print(f"pneu sim: {i}/{n} steps ({100.0 * i / n:.0f} %)", file=sys.stderr, flush=True)

    live = live_options.open_live(
        args, axes=("linear", "rotary"), kind="both", controller_state=False
    )
    with signals.deferred(), claim:
        try:
            rows = simulate(
                params,
                duration,
                args.linear_voltage,
                args.rotary_voltage,
                args.seed,
                progress,
                live=live,
            )
            if live is not None:
                live.close()
                live = None
            stopped = signals.pending()
            marker = (
                f"interrupted by {signals.signal_name(stopped)} at {rows[-1, 0]:.3f} s of "
                f"{duration:g} s"
                if stopped is not None
                else ""
            )
            _write_csv(claim.partial("sim.csv"), rows, marker)
            claim.publish("sim.csv")
            if not args.no_plot:
                title = (
                    f"pneu sim: u_linear {args.linear_voltage:g} V, u_rotary "
                    f"{args.rotary_voltage:g} V, seed {args.seed}"
                    + (f" ({marker})" if marker else "")
                )
                _plot(rows, claim.partial("sim.png"), title)
                claim.publish("sim.png")
        except BaseException:
            claim.discard()
            raise
        finally:
            if live is not None:
                live.close()
    T = params.sim.T
    n_end = max(1, min(len(rows), round(0.1 / T)))  # end position: last 100 ms of laser samples
    x_end_mm = 1e3 * float(np.mean(rows[-n_end:, 6]))
    n_ss = max(1, min(len(rows) - 1, round(1.0 / T)))  # steady speed: last 1 s of encoder speed
    w_ss = float(np.mean(rows[-n_ss:, 8]))
    print(f"end position: {x_end_mm:.2f} mm (laser, mean of the last {n_end * T * 1e3:.0f} ms)")
    print(
        f"steady speed: {w_ss * RPM_PER_RAD_S:.1f} rpm (encoder, mean of the last {n_ss * T:.2f} s)"
    )
    print(f"wrote {claim.final('sim.csv')}")
    if not args.no_plot:
        print(f"wrote {claim.final('sim.png')}")
    if signals.pending() is not None:
        print(
            f"pneu sim: interrupted by {signals.signal_name(signals.pending())} at "
            f"{rows[-1, 0]:.3f} s of {duration:g} s: the files hold what ran",
            file=sys.stderr,
        )
        return exits.interrupted_code(signals.pending())
    if not math.isfinite(x_end_mm):
        return exits.RUNTIME_ERROR
    return exits.OK
