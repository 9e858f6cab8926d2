"""The one parser of ``KIND[:key=value,...]`` strings and of typed command-line values.

The same syntax names a reference (``sine:amplitude=20,frequency_hz=0.25``),
a fault (``controller_silent:axis=linear,start_s=1``) and their launch
arguments; ``--set KEY=VALUE`` values are read like the values here.
"""

from __future__ import annotations

from collections.abc import Collection
from typing import Any

from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.yaml_file import read_scalar

__all__ = ["parse_number", "parse_spec", "parse_value"]

_INF_NAN = {"inf", "+inf", "-inf", "infinity", "+infinity", "-infinity", "nan"}


def parse_value(text: str) -> Any:
    """A value as the config files' reader reads it (``1`` int, ``1.0`` and ``3e5`` float,
    ``true`` bool, ``pid`` str), as the user typed it: ``010`` is the decimal 10, ``0x10``
    16; ``1:00``, ``1_000``, ``yes`` stay strings (YAML 1.1 would read 60, 1000, true), so a
    number or boolean field refuses them (:func:`pneu_msgs_py.params.yaml_file.read_scalar`).
    """
    return read_scalar(text)


def parse_number(text: str, want: type = float) -> float | int:
    """A number option as typed, read like the config files (``010`` 10, ``0x10`` 16,
    ``3e5``; ``inf``/``nan`` words kept for the option's range to judge); ``want``: ``int``
    or ``float``. ``1_000`` and ``1:00`` are not numbers (Python's ``float`` would read
    1000, YAML 1.1 60): :class:`ValueError`, with the text to show."""
    if want is float and text.strip().lower() in _INF_NAN:
        return float(text)
    v = read_scalar(text)
    ok = (int,) if want is int else (int, float)
    if isinstance(v, bool) or not isinstance(v, ok):
        what = "an integer" if want is int else "a number"
        raise ValueError(f"{text!r} is not {what} (read as typed: 1_000 and 1:00 are not numbers)")
    return want(v)


def parse_spec(
    text: str, field: str, keys: Collection[str] | None = None
) -> tuple[str, dict[str, Any]]:
    """``KIND[:key=value,...]`` -> ``(KIND, {key: value})``; ``field`` names the option in errors;
    ``keys``: the only keys allowed (None: any, checked by the caller).

    Refused with one :class:`ParamError` line: an empty kind, an item without
    ``=`` or without a key, a key given twice, and a key ``kind`` (the kind is the
    part before ``:``; a ``kind=`` inside would silently replace it).
    """
    kind, _, rest = text.strip().partition(":")
    kind = kind.strip()
    if not kind:
        raise ParamError(field, text, "KIND[:key=value,...] with a KIND")
    out: dict[str, Any] = {}
    for part in filter(None, (p.strip() for p in rest.split(","))):
        key, sep, value = part.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ParamError(f"{field} {kind}", part, "key=value")
        if key in out:
            raise ParamError(f"{field} {kind}", key, "each key once")
        if keys is not None and key not in keys:
            raise ParamError(f"{field} {kind}", key, "one of " + ", ".join(keys))
        if key == "kind":
            raise ParamError(
                f"{field} {kind}", part, f"no key 'kind': the kind is written before ':' ({kind})"
            )
        out[key] = parse_value(value)
    return kind, out
