"""Checks of a whole run before it starts: what no single parameter's range can catch.

- a linear reference must stay inside the stroke's soft limits (a reference
  beyond them drives the piston into the end stop: the supervisor can only
  hold the valve, see :mod:`pneu_driver.safety.supervisor`);
- a rotary speed reference must stay below the overspeed limit; a rotary angle
  reference (``rotary_control: angle``) inside the angle soft limits when they are
  on, and its rate below the overspeed limit;
- a fault must start inside the run and act on an active axis.

Each refusal is one :class:`ParamError` naming the option as the user wrote it.
"""

from __future__ import annotations

import math
from typing import Any

from pneu_msgs_py.contract.samples import AXES as ALL_AXES
from pneu_msgs_py.contract.units import MM_PER_M
from pneu_msgs_py.params.core import ParamError

from pneu_control.controller.references import axis_scale, make_reference

__all__ = ["check_faults", "check_references", "reference_extremes"]


def reference_extremes(
    params: Any, axis: str, duration_s: float, rate: bool = False
) -> tuple[float, float]:
    """(min, max) of the reference over the run, in paper units (mm, rpm or degrees);
    ``rate``: of its rate instead (mm/s, rpm/s or °/s).

    Evaluated at every control period of the run: the controller sees exactly
    these values (closed forms would miss a waypoint spline's overshoot).
    """
    T = params.sample_time_s
    control = getattr(params, "rotary_control", "speed")
    ref = make_reference(params.reference, axis, sample_time_s=T, rotary_control=control)
    i = 1 if rate else 0
    n = int(round(duration_s / T))
    step = max(1, n // 200_000)  # every sample up to 200 s, then every few (a smooth reference)
    lo = hi = ref(0.0)[i]
    for k in range(0, n + 1, step):
        r = ref(k * T)[i]
        lo, hi = min(lo, r), max(hi, r)
    r_end = ref(n * T)[i]
    scale = axis_scale(axis, control)
    return min(lo, r_end) * scale, max(hi, r_end) * scale


def check_references(spec: Any, field: str | None = None) -> None:
    """Refuse a linear reference outside the soft limits, a rotary one above the overspeed limit.

    Without a supervisor (``spec.safety`` None) the limits are the physical ones: the
    end stops and the rated speed. ``field`` names the option the reference came from
    (default ``<axis>.reference``).
    """
    from pneu_driver.safety import SafetyParams

    safety = spec.safety if spec.safety is not None else SafetyParams()
    supervised = spec.safety is not None
    for axis in spec.axes:
        params = spec.controllers[axis]
        name = field or f"{axis}.reference"
        if field and len(spec.axes) > 1:
            name = f"{field} ({axis})"
        lo, hi = reference_extremes(params, axis, spec.duration_s)
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise ParamError(name, _label(params), "a reference with finite values")
        if axis == "linear":
            margin = safety.stroke_margin_m if supervised else 0.0
            limit = (safety.stroke_m / 2.0 - margin) * MM_PER_M
            bad = hi if hi > limit else lo if lo < -limit else None
            if bad is not None:
                what = (
                    f"the soft limits [{-limit:g}, {limit:g}] mm (stroke "
                    f"{safety.stroke_m * MM_PER_M:g} mm less {margin * MM_PER_M:g} mm per end)"
                    if supervised
                    else f"the end stops [{-limit:g}, {limit:g}] mm"
                )
                raise ParamError(
                    name,
                    _label(params),
                    f"a position reference inside {what}; this one reaches {bad:.4g} mm",
                )
        elif params.rotary_control == "angle":
            _check_angle(name, params, spec.duration_s, lo, hi, safety, supervised)
        else:
            limit = safety.max_speed_rpm if supervised else safety.rated_speed_rpm
            peak = max(abs(lo), abs(hi))
            if peak > limit:
                what = "the overspeed limit max_speed_rpm" if supervised else "the rated speed"
                raise ParamError(
                    name,
                    _label(params),
                    f"a speed reference within ±{limit:g} rpm ({what}); this one reaches "
                    f"{peak:.5g} rpm",
                )


def _check_angle(
    name: str, params: Any, duration_s: float, lo: float, hi: float, safety: Any, supervised: bool
) -> None:
    """An angle reference (degrees): inside the angle soft limits when they are on, its rate
    within the overspeed limit (the rated speed without a supervisor)."""
    if supervised and safety.angle_limits:
        a_lo = safety.angle_min_deg + safety.angle_margin_deg
        a_hi = safety.angle_max_deg - safety.angle_margin_deg
        bad = hi if hi > a_hi else lo if lo < a_lo else None
        if bad is not None:
            raise ParamError(
                name,
                _label(params),
                f"an angle reference inside the angle soft limits [{a_lo:g}, {a_hi:g}]° "
                f"(angle_min_deg/angle_max_deg less angle_margin_deg per end); this one "
                f"reaches {bad:.5g}°",
            )
    limit = safety.max_speed_rpm if supervised else safety.rated_speed_rpm
    w_lo, w_hi = reference_extremes(params, "rotary", duration_s, rate=True)
    peak = max(abs(w_lo), abs(w_hi)) / 6.0  # °/s -> rpm
    if peak > limit:
        what = "the overspeed limit max_speed_rpm" if supervised else "the rated speed"
        raise ParamError(
            name,
            _label(params),
            f"an angle reference turning within ±{limit:g} rpm ({what}); this one turns at "
            f"{peak:.5g} rpm",
        )


def _label(params: Any) -> str:
    """``KIND:key=value,...`` of the reference fields that matter for its kind."""
    r = params.reference
    keys = {
        "sine": ("amplitude", "frequency_hz", "offset"),
        "smooth_step": ("offset", "target", "duration_s"),
        "constant": ("value",),
        "ramp": ("offset", "slope", "duration_s"),
        "waypoints": ("file",),
    }.get(r.kind, ())
    return f"{r.kind}:" + ",".join(
        f"{k}={getattr(r, k):g}" if k != "file" else f"file={r.file}" for k in keys
    )


def check_faults(faults: tuple[Any, ...], axes: tuple[str, ...], duration_s: float) -> None:
    """Every fault starts inside the run and acts on an active axis."""
    for f in faults:
        if not f.start_s < duration_s:
            raise ParamError(
                f"--fault {f.name}.start_s",
                f.start_s,
                f"[0, {duration_s:g}) s: inside the run (--duration {duration_s:g})",
            )
        acts_on = f.axes(ALL_AXES)
        if f.name.startswith("controller_"):
            acts_on = f.axes(axes)
        if not set(acts_on) & set(axes):
            where = ", ".join(f.axes(ALL_AXES)) or "an inactive controller"
            raise ParamError(
                "--fault",
                f.label,
                f"a fault on an active axis ({', '.join(axes)}); this one acts on {where}",
            )
