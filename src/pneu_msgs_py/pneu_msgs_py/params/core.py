"""Parameter dataclasses: one declaration, validated in one place.

Every parameter group in pneu is a frozen dataclass whose fields are made with
:func:`param`. The field metadata (unit, allowed range, description, source,
read-only flag, choices) drives, from a single declaration:

- :func:`validate` -- type, finiteness, range and choice checks, plus the
  group's own cross-field ``_check()`` method if it has one;
- :func:`from_dict` -- strict loading from YAML-shaped dicts (missing key,
  unknown key, wrong type all refused, nothing half-loaded);
- :func:`flatten` / :func:`with_updates` -- dotted names as ROS 2 parameters
  use them (``eso_smc.epsilon``), and a whole-set update that is validated
  as one and leaves the old object untouched when refused;
- :func:`describe` -- what an rclpy shell turns into ``ParameterDescriptor``.

No rclpy here: shells convert :class:`ParamSpec` into descriptors themselves.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

__all__ = [
    "MISSING",
    "ParamError",
    "ParamSpec",
    "shown",
    "unknown_key",
    "param",
    "validate",
    "from_dict",
    "to_dict",
    "flatten",
    "with_updates",
    "describe",
]


class _Missing:
    """The value of a required key that is not there."""

    def __repr__(self) -> str:
        return "missing"


MISSING = _Missing()


SHOWN_CHARS = 200  # a refused value is shown up to this long (a path fits): one short line


def shown(value: Any) -> str:
    """``value`` as a refusal shows it: its repr, a mapping or list by its size and first
    keys (never a whole YAML tree), long text cut to :data:`SHOWN_CHARS` characters."""
    if isinstance(value, Mapping) and not value:
        text = "an empty mapping {}"
    elif isinstance(value, Mapping):
        keys = ", ".join(str(k) for k in list(value)[:4]) + (", ..." if len(value) > 4 else "")
        text = f"a mapping ({len(value)} key{'s' * (len(value) != 1)}: {keys})"
    elif isinstance(value, (list, tuple)) and (len(value) > 6 or len(repr(value)) > SHOWN_CHARS):
        text = f"a list of {len(value)} items"  # a table's values: its size says enough
    else:
        text = repr(value)
    if len(text) > SHOWN_CHARS:
        quote = text[0] if text[0] in "'\"" else ""
        text = text[: SHOWN_CHARS - 4] + "..." + quote
    return text


def unknown_key(key: Any, known: Iterable[str], shown_chars: int = 80) -> str:
    """The ``allowed`` text for an unknown key: the close names first, then the known ones
    (as many as fit in ``shown_chars``, the count said): one short line for any group."""
    import difflib

    known = list(known)
    close = difflib.get_close_matches(str(key), known, n=3, cutoff=0.6)
    names: list[str] = []
    for name in known:
        if names and len(", ".join([*names, name])) > shown_chars:
            break
        names.append(name)
    listed = ", ".join(names) + (f", ... ({len(known)} in all)" if len(names) < len(known) else "")
    hint = f"; did you mean {' or '.join(close)}?" if close else ""
    return f"no such parameter{hint}; known: {listed}"


class ParamError(ValueError):
    """A parameter value was refused; the message names the key, value and range.

    ``value`` :data:`MISSING`: the key is required and absent (``key: missing; required: ...``).
    The value is shown short (:func:`shown`): one line, whatever was refused.
    """

    def __init__(self, key: str, value: Any, allowed: str):
        self.key = key
        self.value = value
        self.allowed = allowed
        if value is MISSING:
            super().__init__(f"{key}: missing; required: {allowed}")
        else:
            super().__init__(f"{key}: {shown(value)} refused; allowed: {allowed}")


def param(
    default: Any = dataclasses.MISSING,
    *,
    unit: str = "",
    desc: str = "",
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    choices: tuple[str, ...] | None = None,
    source: str = "",
    read_only: bool = False,
    band: tuple[float, float] | None = None,
    alternatives: tuple[tuple[str, float], ...] | None = None,
    allowed: str = "",
) -> Any:
    """A dataclass field with pneu metadata.

    ``lo``/``hi`` are inclusive bounds unless ``lo_open``/``hi_open``.
    ``read_only`` marks values whose change needs a restart (ROS descriptor).
    ``band`` (lo, hi) is the range an uncertain value may take (its reason in
    ``source``); ``alternatives`` ((label, value), ...) are discrete readings
    of it. Neither is checked here: the file that carries them checks them.
    ``allowed`` replaces the printed range where the true one depends on another
    field (checked by the group's ``_check``), so a refusal never prints a wrong range.
    """
    meta = {
        "pneu": True,
        "unit": unit,
        "desc": desc,
        "lo": lo,
        "hi": hi,
        "lo_open": lo_open,
        "hi_open": hi_open,
        "choices": choices,
        "source": source,
        "read_only": read_only,
        "band": band,
        "alternatives": alternatives,
        "allowed": allowed,
    }
    if dataclasses.is_dataclass(default) and not isinstance(default, type):
        return dataclasses.field(default_factory=lambda d=default: d, metadata=meta)
    if isinstance(default, type) and dataclasses.is_dataclass(default):
        return dataclasses.field(default_factory=default, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


@dataclass(frozen=True)
class ParamSpec:
    """One flattened parameter, as an rclpy shell declares it."""

    name: str
    default: Any
    type: type
    unit: str
    description: str
    lo: float | None
    hi: float | None
    read_only: bool
    choices: tuple[str, ...] | None


def _allowed_text(meta: Mapping[str, Any], typ: type) -> str:
    if meta.get("allowed"):
        return meta["allowed"]
    if meta.get("choices"):
        return "one of " + ", ".join(meta["choices"])
    lo, hi = meta.get("lo"), meta.get("hi")
    unit = f" {meta['unit']}" if meta.get("unit") else ""
    if typ is bool:
        return "true or false"
    if typ is str:
        return "a string"
    if typing.get_origin(typ) is tuple:
        return f"a list of finite numbers{unit}"
    if lo is None and hi is None:
        return f"any finite {typ.__name__}{unit}"
    # values are finite: an open end is never included
    left = "(" if meta.get("lo_open") or lo is None else "["
    right = ")" if meta.get("hi_open") or hi is None else "]"
    lo_s = "-inf" if lo is None else f"{lo:g}"
    hi_s = "inf" if hi is None else f"{hi:g}"
    return f"{left}{lo_s}, {hi_s}{right}{unit}"


@functools.cache
def _field_types(cls: type) -> dict[str, Any]:
    """The resolved field annotations of a parameter dataclass (cached: read only)."""
    return typing.get_type_hints(cls)


def _base_type(tp: Any) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return args[0] if len(args) == 1 else tp
    return tp


def _check_value(key: str, value: Any, tp: Any, meta: Mapping[str, Any]) -> Any:
    """Coerce (int -> float only) and check one scalar value; return it."""
    tp = _base_type(tp)

    def allowed() -> str:  # built only for the error message
        return _allowed_text(meta, tp if isinstance(tp, type) else float)

    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParamError(key, value, f"a number, {allowed()}")
        value = float(value)
        if not math.isfinite(value):
            raise ParamError(key, value, allowed())
    elif tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParamError(key, value, f"an integer, {allowed()}")
    elif tp is bool:
        if not isinstance(value, bool):
            raise ParamError(key, value, "true or false")
        return value
    elif tp is str:
        if not isinstance(value, str):
            plain = not (meta.get("allowed") or meta.get("choices"))  # "a string" says it all
            raise ParamError(key, value, "a string" if plain else f"a string, {allowed()}")
    elif typing.get_origin(tp) is tuple:
        if not isinstance(value, (list, tuple)):
            raise ParamError(key, value, "a list of numbers")
        if all(type(v) is float for v in value) and all(map(math.isfinite, value)):
            return tuple(value)  # the common case (a fit sets curves thousands of times)
        out = []
        for i, v in enumerate(value):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ParamError(f"{key}[{i}]", v, "a finite number")
            out.append(float(v))
        return tuple(out)
    else:
        return value
    choices = meta.get("choices")
    if choices and value not in choices:
        raise ParamError(key, value, allowed())
    lo, hi = meta.get("lo"), meta.get("hi")
    if lo is not None and (value < lo or (meta.get("lo_open") and value == lo)):
        raise ParamError(key, value, allowed())
    if hi is not None and (value > hi or (meta.get("hi_open") and value == hi)):
        raise ParamError(key, value, allowed())
    return value


def validate(obj: Any, prefix: str = "") -> Any:
    """Check every field of ``obj`` (recursively) and its ``_check()``; return ``obj``."""
    hints = _field_types(type(obj))
    for f in dataclasses.fields(obj):
        key = f"{prefix}{f.name}"
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            validate(value, prefix=f"{key}.")
        elif f.metadata.get("pneu"):
            checked = _check_value(key, value, hints[f.name], f.metadata)
            if checked != value or type(checked) is not type(value):
                object.__setattr__(obj, f.name, checked)
    return _checked(obj, prefix)


def _checked(obj: Any, prefix: str) -> Any:
    """``obj`` after its own ``_check()`` (a cross-field rule), errors named under ``prefix``."""
    check = getattr(obj, "_check", None)
    if check is not None:
        try:
            check()
        except ParamError as err:
            if prefix and not err.key.startswith(prefix):
                raise ParamError(prefix + err.key, err.value, err.allowed) from None
            raise
    return obj


def from_dict(cls: type, data: Mapping[str, Any], *, strict: bool = True, prefix: str = "") -> Any:
    """Build and validate ``cls`` from a nested mapping.

    ``strict``: every field must be present (plant.yaml); otherwise missing
    fields take their defaults (controller and safety groups). Unknown keys
    are always refused.
    """
    if not isinstance(data, Mapping):
        raise ParamError(prefix.rstrip(".") or cls.__name__, data, "a mapping of parameters")
    hints = _field_types(cls)
    names = {f.name: f for f in dataclasses.fields(cls)}
    for key in data:
        if key not in names:
            raise ParamError(f"{prefix}{key}", data[key], unknown_key(key, names))
    kwargs: dict[str, Any] = {}
    for name, f in names.items():
        key = f"{prefix}{name}"
        tp = _base_type(hints[name])
        if name not in data:
            has_default = (
                f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING
            )
            if strict or not has_default:
                what = (
                    "the parameter group " + ", ".join(x.name for x in dataclasses.fields(tp))
                    if isinstance(tp, type) and dataclasses.is_dataclass(tp)
                    else _allowed_text(f.metadata, tp if isinstance(tp, type) else float)
                )
                raise ParamError(key, MISSING, what)
            continue
        value = data[name]
        if isinstance(tp, type) and dataclasses.is_dataclass(tp):
            kwargs[name] = from_dict(tp, value, strict=strict, prefix=f"{key}.")
        else:
            kwargs[name] = _check_value(key, value, tp, f.metadata)
    # every field was checked above, every group by its own from_dict: the own rule remains
    return _checked(cls(**kwargs), prefix)


def to_dict(obj: Any) -> dict[str, Any]:
    """Nested plain dict (YAML/JSON-ready) of a parameter dataclass."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            out[f.name] = to_dict(value)
        elif isinstance(value, tuple):
            out[f.name] = list(value)
        else:
            out[f.name] = value
    return out


def flatten(obj: Any, prefix: str = "") -> dict[str, Any]:
    """``{"eso_smc.epsilon": 1200.0, ...}`` -- ROS 2 dotted parameter names."""
    out: dict[str, Any] = {}
    for key, value in to_dict(obj).items():
        if isinstance(value, dict):
            sub = _flatten_dict(value, f"{prefix}{key}.")
            out.update(sub)
        else:
            out[f"{prefix}{key}"] = value
    return out


def _flatten_dict(d: Mapping[str, Any], prefix: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in d.items():
        if isinstance(value, Mapping):
            out.update(_flatten_dict(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def with_updates(obj: Any, updates: Mapping[str, Any]) -> Any:
    """A new validated object with dotted-name ``updates`` applied as one set.

    Raises :class:`ParamError` naming the first bad key; ``obj`` is unchanged. Only the
    groups on the updated keys' paths are rebuilt (their fields checked, their ``_check()``
    run, innermost first); the others are ``obj``'s own, already validated.
    """
    known = _leaf_names(type(obj))
    tree = _Group()
    for key, value in updates.items():
        if key not in known:
            raise ParamError(key, value, unknown_key(key, known))
        node = tree
        parts = key.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, _Group())
        node[parts[-1]] = value
    return _rebuilt(obj, tree, "")


class _Group(dict):
    """The updates of one group, by field name (a leaf's value may itself be a mapping)."""


def _rebuilt(obj: Any, tree: _Group, prefix: str) -> Any:
    hints = _field_types(type(obj))
    fields = {f.name: f for f in dataclasses.fields(obj)}
    changes: dict[str, Any] = {}
    for name, value in tree.items():
        key = f"{prefix}{name}"
        if isinstance(value, _Group):
            changes[name] = _rebuilt(getattr(obj, name), value, f"{key}.")
        else:
            changes[name] = _check_value(key, value, hints[name], fields[name].metadata)
    return _checked(dataclasses.replace(obj, **changes), prefix)


@functools.cache
def _leaf_names(cls: type) -> tuple[str, ...]:
    """The dotted names of ``cls``'s leaves (what :func:`flatten` of an instance names)."""
    out: list[str] = []
    hints = _field_types(cls)
    for f in dataclasses.fields(cls):
        tp = _base_type(hints[f.name])
        if isinstance(tp, type) and dataclasses.is_dataclass(tp):
            out.extend(f"{f.name}.{n}" for n in _leaf_names(tp))
        else:
            out.append(f.name)
    return tuple(out)


def describe(cls_or_obj: Any, prefix: str = "") -> list[ParamSpec]:
    """Flattened :class:`ParamSpec` list, defaults taken from ``cls_or_obj``."""
    obj = cls_or_obj() if isinstance(cls_or_obj, type) else cls_or_obj
    hints = _field_types(type(obj))
    specs: list[ParamSpec] = []
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        name = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(value):
            specs.extend(describe(value, prefix=f"{name}."))
            continue
        meta = f.metadata
        tp = _base_type(hints[f.name])
        desc = meta.get("desc", "")
        if meta.get("unit"):
            desc = f"{desc} [{meta['unit']}]"
        if meta.get("source"):
            desc = f"{desc} (source: {meta['source']})"
        specs.append(
            ParamSpec(
                name=name,
                default=list(value) if isinstance(value, tuple) else value,
                type=tp if isinstance(tp, type) else list,
                unit=meta.get("unit", ""),
                description=desc.strip(),
                lo=meta.get("lo"),
                hi=meta.get("hi"),
                read_only=bool(meta.get("read_only")),
                choices=meta.get("choices"),
            )
        )
    return specs
