"""Parameter plumbing between the params framework and an rclpy shell (no rclpy here).

A shell declares every field of its core's parameter dataclass as a ROS 2
parameter, validates a requested change before rclpy stores it, and applies
it after. The decisions live here so they are tested without ROS:

- :func:`declarations` -- ``(name, default, descriptor)`` tuples for
  ``Node.declare_parameters('', ...)``; the descriptor classes are passed in
  (rclpy's, or rosbags' Jazzy typestore classes in tests);
- :func:`descriptor_fields` -- the same descriptor as a plain dict;
- :func:`coerce_value` -- the value a parameter of that spec should carry
  (``ros2 param set x 900`` sends INTEGER 900 to a DOUBLE parameter; the
  shell's pre-set callback turns it into 900.0 instead of a type error);
- :func:`validate_updates` -- one set of changes validated as a whole
  against the current parameters (``with_updates``): ``(ok, reason, new)``,
  the old object untouched on refusal.

rclpy semantics this follows (rclpy 7.1, Jazzy, ``rclpy/node.py``):
descriptor ranges are inclusive and checked by rclpy before the
on-set callbacks run; ``read_only`` is refused by rclpy with
"Trying to set a read-only parameter"; the on-set callback must not reject
parameters it does not own (``use_sim_time``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from typing import Any

from pneu_msgs_py.params.core import ParamError, ParamSpec, describe, flatten, with_updates

__all__ = [
    "PARAMETER_TYPE",
    "coerce_value",
    "declarations",
    "descriptor_fields",
    "allowed_text",
    "field_metadata",
    "specs_by_name",
    "validate_updates",
    "values_to_overrides",
]

# rcl_interfaces/msg/ParameterType constants (Jazzy)
PARAMETER_TYPE = {bool: 1, int: 2, float: 3, str: 4, list: 8}


def specs_by_name(params_or_cls: Any, prefix: str = "") -> dict[str, ParamSpec]:
    """``{dotted name: ParamSpec}`` for a parameter dataclass (or instance)."""
    return {s.name: s for s in describe(params_or_cls, prefix=prefix)}


def field_metadata(params_or_cls: Any, prefix: str = "") -> dict[str, Mapping[str, Any]]:
    """``{dotted name: params-framework field metadata}`` (bounds openness included)."""
    obj = params_or_cls() if isinstance(params_or_cls, type) else params_or_cls
    out: dict[str, Mapping[str, Any]] = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            out.update(field_metadata(value, prefix=f"{prefix}{f.name}."))
        else:
            out[f"{prefix}{f.name}"] = f.metadata
    return out


def allowed_text(spec: ParamSpec, meta: Mapping[str, Any] | None = None) -> str:
    """The allowed values in words: ``(0, inf] 1/s``, ``one of pid, ladrc``, ...

    ``meta`` (from :func:`field_metadata`) supplies open bounds, which
    :class:`ParamSpec` does not carry; without it bounds print as closed.
    """
    meta = meta or {}
    if spec.choices:
        return "one of " + ", ".join(spec.choices)
    if spec.type is bool:
        return "true or false"
    if spec.type is str:
        return "a string"
    if spec.lo is None and spec.hi is None:
        return "any finite number" + (f" [{spec.unit}]" if spec.unit else "")
    left = "(" if meta.get("lo_open") or spec.lo is None else "["
    right = ")" if meta.get("hi_open") or spec.hi is None else "]"
    lo = "-inf" if spec.lo is None else f"{spec.lo:g}"
    hi = "inf" if spec.hi is None else f"{spec.hi:g}"
    unit = f" {spec.unit}" if spec.unit else ""
    return f"{left}{lo}, {hi}{right}{unit}"


def _range(spec: ParamSpec) -> tuple[float, float] | None:
    """An inclusive descriptor range, only when both bounds are finite.

    A one-sided bound (``lo=0``, no ``hi``) is left to :func:`validate_updates`
    and written into ``additional_constraints``: an infinite bound in a
    descriptor breaks GUI sliders (rqt_reconfigure) and says nothing useful.
    """
    if spec.lo is None or spec.hi is None:
        return None
    if not (math.isfinite(spec.lo) and math.isfinite(spec.hi)):
        return None
    return float(spec.lo), float(spec.hi)


def descriptor_fields(spec: ParamSpec, meta: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Every ``rcl_interfaces/msg/ParameterDescriptor`` field, as plain data.

    Ranges are lists of plain dicts (``from_value``, ``to_value``, ``step``);
    ``additional_constraints`` states the allowed values in words.
    """
    rng = _range(spec)
    fp, ir = [], []
    if rng is not None and spec.type is float:
        fp = [{"from_value": rng[0], "to_value": rng[1], "step": 0.0}]
    elif rng is not None and spec.type is int:
        ir = [{"from_value": math.ceil(rng[0]), "to_value": math.floor(rng[1]), "step": 0}]
    return {
        "name": spec.name,
        "type": PARAMETER_TYPE.get(spec.type, 0),
        "description": spec.description,
        "additional_constraints": allowed_text(spec, meta),
        "read_only": bool(spec.read_only),
        "dynamic_typing": False,
        "floating_point_range": fp,
        "integer_range": ir,
    }


def declarations(
    params: Any,
    ParameterDescriptor: type,
    FloatingPointRange: type,
    IntegerRange: type,
    prefix: str = "",
) -> list[tuple[str, Any, Any]]:
    """``[(name, default, descriptor), ...]`` for ``Node.declare_parameters('', ...)``.

    Defaults are the values of ``params`` (e.g. as loaded from
    ``config/controllers.yaml``); ROS overrides (``--params-file``, launch
    ``parameters=``) still win inside rclpy. Every descriptor field is passed
    by keyword, so rclpy's message classes and rosbags' dataclasses both
    construct.
    """
    metas = field_metadata(params, prefix=prefix)
    out = []
    for spec in describe(params, prefix=prefix):
        d = descriptor_fields(spec, metas.get(spec.name))
        fp = [FloatingPointRange(**r) for r in d.pop("floating_point_range")]
        ir = [IntegerRange(**r) for r in d.pop("integer_range")]
        desc = ParameterDescriptor(**d, floating_point_range=fp, integer_range=ir)
        default = coerce_value(spec, spec.default)
        if spec.type is list and not default:
            raise ParamError(spec.name, default, "a non-empty list (ROS infers the type from it)")
        out.append((spec.name, default, desc))
    return out


def coerce_value(spec: ParamSpec, value: Any) -> Any:
    """The value with the spec's ROS type where that loses nothing.

    int -> float for DOUBLE parameters (``ros2 param set ... 900``); any
    sequence (``array.array`` from rclpy) -> list of float for arrays.
    Anything else is returned unchanged for validation to refuse.
    """
    if spec.type is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if spec.type is list and not isinstance(value, (str, bytes)) and hasattr(value, "__iter__"):
        items = list(value)
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in items):
            return [float(v) for v in items]
        return items
    return value


def validate_updates(
    current: Any, updates: Iterable[tuple[str, Any]], *, startup: bool = False
) -> tuple[bool, str, Any]:
    """Validate a set of parameter changes as one; ``(ok, reason, new_params)``.

    Names ``current`` does not have (``use_sim_time``, other groups) are
    ignored, not refused. A change to a read-only parameter is refused (rclpy
    refuses it too, before this runs). The whole set goes through
    ``with_updates``, so cross-field checks (``_check``) see the new values
    together; on refusal ``new_params is current`` and ``reason`` names the
    parameter, the value and the allowed range. ``startup=True`` accepts
    read-only values (the node's initial overrides).
    """
    specs = specs_by_name(current)
    known = flatten(current)
    changes: dict[str, Any] = {}
    for name, value in updates:
        spec = specs.get(name)
        if spec is None:
            continue
        value = coerce_value(spec, value)
        if spec.read_only and not startup and value != known[name]:
            return False, f"{name}: read-only (a change needs a restart)", current
        changes[name] = value
    if not changes:
        return True, "", current
    try:
        new = with_updates(current, changes)
    except ParamError as err:
        return False, str(err), current
    return True, "", new


def values_to_overrides(params: Any) -> dict[str, Any]:
    """``{dotted name: value}`` in ROS types (lists for tuples) of a parameter object."""
    specs = specs_by_name(params)
    return {k: coerce_value(specs[k], v) for k, v in flatten(params).items()}
