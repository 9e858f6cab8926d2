"""Controller parameter groups (one frozen dataclass each) and the YAML loader.

Gains are typed in the paper's units (DESIGN §5): the linear controller works
in mm (position), the rotary controller in rpm (speed). Each field's unit
string gives both readings, ``linear | rotary``. Topics, samples and the twin
stay SI; :class:`pneu_control.controller.axis.AxisController` converts at its boundary.

``config/controllers.yaml`` is a ROS 2 params file::

    linear_controller:
      ros__parameters:
        algorithm: eso_smc
        pid: {kp: 0.38, ...}
        ...

:func:`load_controller_params` reads ``<axis>_controller.ros__parameters``,
applies dotted overrides (``{"eso_smc.epsilon": 900}``) and validates the
whole set once (nothing half-applied).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pneu_msgs_py.lifecycle.duration import MAX_DURATION_S
from pneu_msgs_py.params.core import (
    MISSING,
    ParamError,
    flatten,
    from_dict,
    param,
    with_updates,
)
from pneu_msgs_py.params.yaml_file import load_yaml, located

from pneu_control.algorithms import (
    CoastParams,
    EsoSmcParams,
    EsoSmcPlusParams,
    LadrcParams,
    PidParams,
    PvaParams,
)

__all__ = [
    "ALGORITHMS",
    "ANGLE_ONLY_ALGORITHMS",
    "AXIS_ALGORITHMS",
    "REFERENCE_KEYS",
    "REFERENCE_KINDS",
    "TdParams",
    "LimitsParams",
    "ReferenceParams",
    "AxisControllerParams",
    "load_controller_params",
    "omega_0_max",
    "ParamError",
]

ALGORITHMS = ("pid", "ladrc", "eso_smc", "eso_smc_plus", "coast", "pva")
# coast and pva position a rotary angle only (rotary_control: angle); the others run on every
# axis
ANGLE_ONLY_ALGORITHMS = ("coast", "pva")
AXIS_ALGORITHMS = tuple(a for a in ALGORITHMS if a not in ANGLE_ONLY_ALGORITHMS)
REFERENCE_KINDS = ("sine", "smooth_step", "constant", "ramp", "waypoints")
# the ReferenceParams fields each kind reads (references.make_reference): a key of another
# kind given with it would be silently ignored (constant:value=5,amplitude=3)
REFERENCE_KEYS = {
    "sine": ("amplitude", "frequency_hz", "offset", "t0_s"),
    "smooth_step": ("offset", "target", "duration_s", "t0_s"),
    "constant": ("value",),
    "ramp": ("offset", "slope", "duration_s", "t0_s"),
    "waypoints": ("file", "t0_s"),
}

_POS = {"lo": 0.0, "lo_open": True}  # strictly positive
_NONNEG = {"lo": 0.0}


@dataclass(frozen=True)
class TdParams:
    """Tracking differentiator (Eq. 23–24, fhan of Han 2009) on the reference.

    ``r`` bounds the reference acceleration d²v1/dt² (mm/s² linear, rpm/s²
    rotary); ``h`` is fhan's filter factor h0 (≥ the sample time).
    Used by LADRC and ESO-SMC; PID uses the reference directly.
    """

    enabled: bool = param(True, desc="use the TD; off = analytic reference derivatives")
    r: float = param(50000.0, unit="mm/s² | rpm/s²", desc="speed factor r", **_POS, source="paper")
    h: float = param(
        0.001, unit="s", desc="filter factor h (≥ sample time)", **_POS, source="paper"
    )


@dataclass(frozen=True)
class LimitsParams:
    """Valve command limits: MPYE 0–10 V, 5 V closed centre."""

    u_min: float = param(0.0, unit="V", desc="lowest valve command", lo=0.0, hi=10.0)
    u_max: float = param(10.0, unit="V", desc="highest valve command", lo=0.0, hi=10.0)
    u_neutral: float = param(5.0, unit="V", desc="closed-centre command (u = 0)", lo=0.0, hi=10.0)

    def _check(self) -> None:
        if not self.u_min < self.u_neutral < self.u_max:
            # a relation of three fields: name all three (whichever the user changed)
            raise ParamError(
                "u_min/u_neutral/u_max",
                f"{self.u_min:g}/{self.u_neutral:g}/{self.u_max:g} V",
                "u_min < u_neutral < u_max (the closed centre strictly inside the range)",
            )


@dataclass(frozen=True)
class ReferenceParams:
    """Reference signal, in paper units (mm linear position, rpm rotary speed).

    kinds:
      - ``sine``: offset + amplitude·sin(2π f (t − t0))
      - ``smooth_step``: Eq. 38 generalised, offset → target in duration_s
      - ``constant``: value
      - ``ramp``: offset + slope·(t − t0), held after duration_s (0 = never)
      - ``waypoints``: quintic Hermite through (t, value) rows of ``file``
    Before ``t0_s`` every kind holds its value at t0.
    """

    kind: str = param("sine", choices=REFERENCE_KINDS, desc="reference type")
    amplitude: float = param(20.0, unit="mm | rpm", desc="sine amplitude", source="paper")
    frequency_hz: float = param(
        0.25,
        unit="Hz",
        desc="sine frequency",
        lo=1.0 / MAX_DURATION_S,
        allowed=f"[1/{MAX_DURATION_S:g}, 1/(2·sample_time_s)) Hz: at least one period in the "
        f"longest run ({MAX_DURATION_S:g} s, the duration cap) and below the Nyquist frequency "
        "(500 Hz at the paper's T = 1 ms)",
        source="paper",
    )
    offset: float = param(0.0, unit="mm | rpm", desc="sine offset; start of smooth_step and ramp")
    target: float = param(
        120.0 / math.pi, unit="mm | rpm", desc="smooth_step end value", source="paper Eq. 38"
    )
    duration_s: float = param(
        4.0,
        unit="s",
        desc="smooth_step duration; ramp duration (0 = endless)",
        lo=0.0,
        hi=MAX_DURATION_S,  # longer never completes in any run (the duration cap)
        source="paper Eq. 38",
    )
    value: float = param(800.0, unit="mm | rpm", desc="constant value", source="paper (800 rpm)")
    slope: float = param(0.0, unit="mm/s | rpm/s", desc="ramp slope")
    file: str = param("", desc="waypoint file (CSV t,value or YAML), paper units")
    t0_s: float = param(
        0.0,
        unit="s",
        desc="start time; the reference holds before it",
        lo=0.0,
        hi=MAX_DURATION_S,  # later never starts in any run (the duration cap)
    )

    def _check(self) -> None:
        if self.kind == "smooth_step" and self.duration_s <= 0.0:
            raise ParamError("duration_s", self.duration_s, "(0, inf) s for a smooth_step")
        if self.kind == "waypoints" and not self.file:
            raise ParamError("file", self.file, "a CSV or YAML waypoint file for kind waypoints")


def omega_0_max(sample_time_s: float) -> float:
    """Largest accepted observer bandwidth: the Nyquist frequency π/T (rad/s).

    The ZOH current observer is stable for every ω0 > 0 (poles exp(−ω0 T));
    above π/T a continuous bandwidth has no meaning on the sampled signal.
    """
    return math.pi / sample_time_s


@dataclass(frozen=True)
class AxisControllerParams:
    """Everything one axis controller needs, validated as one set."""

    algorithm: str = param("eso_smc", choices=ALGORITHMS, desc="active control algorithm")
    pid: PidParams = param(PidParams)
    ladrc: LadrcParams = param(LadrcParams)
    eso_smc: EsoSmcParams = param(EsoSmcParams)
    eso_smc_plus: EsoSmcPlusParams = param(EsoSmcPlusParams)
    coast: CoastParams = param(CoastParams)
    pva: PvaParams = param(PvaParams)
    td: TdParams = param(TdParams)
    limits: LimitsParams = param(LimitsParams)
    reference: ReferenceParams = param(ReferenceParams)
    sample_time_s: float = param(
        0.001,
        unit="s",
        desc="controller period T",
        lo=0.0,
        lo_open=True,
        hi=0.1,
        read_only=True,
        source="paper (1 ms)",
    )
    transport_delay_samples: int = param(
        1,
        desc="samples between a sample and the start of the command computed from it (DESIGN §3); "
        "the ESO predicts with the command actually on the valve",
        lo=0,
        hi=5,
        read_only=True,
    )
    rotary_control: str = param(
        "speed",
        choices=("speed", "angle"),
        desc="what the rotary axis controls: its speed (rpm, the paper's experiment) or its "
        "multi-turn angle on the encoder (degrees: references, gains and errors in °); "
        "ignored on the linear axis",
        read_only=True,
    )
    rotary_model: str = param(
        "speed",
        choices=("speed", "angle"),
        desc="rotary LADRC/ESO-SMC plant model: speed (ω̈ = f + b0 u, b0 rpm/s²/V) or angle "
        "(θ̈ = f + b0 u on θ_r = ∫ω_r, b0 rpm/s/V); ignored on the linear axis",
        read_only=True,
    )
    bumpless_time_s: float = param(
        0.1,
        unit="s",
        desc="time constant of the decaying offset that blends a switched algorithm's first "
        "command into the last one (no jump; per-sample change ≤ offset·T/τ)",
        lo=0.0,
        lo_open=True,
        hi=10.0,
    )

    def _check(self) -> None:
        T = self.sample_time_s
        if self.rotary_control == "angle" and self.rotary_model == "angle":
            raise ParamError(
                "rotary_model",
                self.rotary_model,
                "speed with rotary_control: angle (the angle is then the controlled output)",
            )
        smc = self.eso_smc
        if smc.friction_compensation:
            from pneu_msgs_py.contract.units import RPM_PER_RAD_S

            c_max = RPM_PER_RAD_S / smc.J_m * (smc.M_v + smc.M_c / smc.coulomb_smoothing)
            if c_max * T >= 1.0:
                ws_min = smc.M_c / (1.0 / (T * RPM_PER_RAD_S / smc.J_m) - smc.M_v)
                raise ParamError(
                    "eso_smc.coulomb_smoothing",
                    smc.coulomb_smoothing,
                    f"({ws_min:.6g}, inf) rpm so that the friction damping gain "
                    f"c = κ(M_v + M_c/ω_s)/J_m stays below 1/T (now {c_max:.4g} 1/s)",
                )
        w_max = omega_0_max(T)
        for group in ("ladrc", "eso_smc", "eso_smc_plus"):
            w0 = getattr(self, group).omega_0
            if w0 > w_max:
                raise ParamError(
                    f"{group}.omega_0", w0, f"(0, {w_max:.6g}] rad/s (π/T at T = {T:g} s)"
                )
        f_nyq = 0.5 / T
        if self.reference.frequency_hz >= f_nyq:
            raise ParamError(
                "reference.frequency_hz",
                self.reference.frequency_hz,
                f"(0, {f_nyq:g}) Hz (below the Nyquist frequency 1/(2T) at T = {T:g} s)",
            )
        if self.td.h < T * (1.0 - 1e-9):
            raise ParamError("td.h", self.td.h, f"[{T:g}, inf) s (at least the sample time)")
        for group in ("eso_smc", "eso_smc_plus"):
            _check_layer(group, getattr(self, group), T)


def _check_layer(group: str, smc: Any, T: float) -> None:
    """The boundary layer of an ESO-SMC group: k·Δ <= 1 and ε·k·T < 1. Each couples two
    fields: the refusal names both (whichever was set) and the range of each at the other's
    value."""
    if smc.k * smc.delta > 1.0 + 1e-12:
        raise ParamError(
            f"{group}.k/{group}.delta",
            f"{smc.k:g}, {smc.delta:g}",
            f"k·Δ <= 1 (sat must not exceed 1 in the layer): k in (0, {1.0 / smc.delta:.6g}] "
            f"at Δ = {smc.delta:g}, or Δ in (0, {1.0 / smc.k:.6g}] at k = {smc.k:g}",
        )
    if smc.epsilon * smc.k * T >= 1.0:
        raise ParamError(
            f"{group}.epsilon/{group}.k",
            f"{smc.epsilon:g}, {smc.k:g}",
            f"ε·k·T < 1 (the discrete boundary layer stable with a one-sample delay, T = {T:g} "
            f"s): k in (0, {1.0 / (smc.epsilon * T):.6g}) at ε = {smc.epsilon:g}, or ε in "
            f"(0, {1.0 / (smc.k * T):.6g}) at k = {smc.k:g}",
        )


def _find_controllers_yaml() -> Path:
    try:
        from pneu_msgs_py.params.paths import config_file

        p = config_file("controllers.yaml")
        if p.is_file():
            return p
    except FileNotFoundError:
        pass
    here = Path(__file__).resolve()
    for parent in here.parents:
        cand = parent / "config" / "controllers.yaml"
        if cand.is_file():
            return cand
    raise FileNotFoundError("config/controllers.yaml not found: set PNEU_CONFIG_DIR")


def _section(data: Any, axis: str, path: Path) -> Mapping[str, Any]:
    key = f"{axis}_controller"
    if not isinstance(data, Mapping) or key not in data:
        raise ParamError(key, MISSING, f"a top-level '{key}:' section")
    node = data[key]
    if not isinstance(node, Mapping) or "ros__parameters" not in node:
        raise ParamError(f"{key}.ros__parameters", MISSING, "a 'ros__parameters:' mapping")
    params = node["ros__parameters"]
    if not isinstance(params, Mapping):
        raise ParamError(f"{key}.ros__parameters", params, "a mapping")
    return params


def params_from_mapping(data: Mapping[str, Any], *, strict: bool = False) -> AxisControllerParams:
    """Build from a nested (YAML-shaped) mapping; ``strict``: every key required (a file),
    else missing keys take defaults (parameters a node reported)."""
    return from_dict(AxisControllerParams, data, strict=strict)


def load_controller_params(
    axis: str,
    path: str | Path | None = None,
    overrides: Mapping[str, object] | None = None,
) -> AxisControllerParams:
    """Read ``<axis>_controller.ros__parameters`` of ``path`` (default config/controllers.yaml).

    The file is read strictly (:mod:`pneu_msgs_py.params.yaml_file`): every
    parameter of the section must be there, none unknown, none twice.

    ``overrides`` are dotted names (``"eso_smc.epsilon": 900``) applied on top
    and validated with the file's values as one set; the reference (and its
    waypoint file) is checked by building it.
    """
    if axis not in ("linear", "rotary"):
        raise ParamError("axis", axis, "one of linear, rotary")
    p = Path(path) if path is not None else _find_controllers_yaml()
    data = load_yaml(p)
    with located(p, data, f"{axis}_controller.ros__parameters"):
        params = params_from_mapping(_section(data, axis, p), strict=True)
    if overrides:
        params = with_updates(params, dict(overrides))
    from pneu_control.controller.references import make_reference

    make_reference(params.reference, axis, sample_time_s=params.sample_time_s)
    return params


def flat_params(params: AxisControllerParams) -> dict[str, Any]:
    """Dotted-name view (what ``ros2 param list`` shows)."""
    return flatten(params)
