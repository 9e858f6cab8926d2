"""The one parser of ``KIND[:key=value,...]`` strings and of typed command-line values.

The same syntax names a reference (``sine:amplitude=20,frequency_hz=0.25``),
a fault (``controller_silent:axis=linear,start_s=1``) and their launch
arguments; ``--set KEY=VALUE`` values are read like the values here.
"""

from __future__ import annotations

from typing import Any

import yaml

from pneu_msgs_py.params.core import ParamError

__all__ = ["parse_spec", "parse_value"]


def parse_value(text: str) -> Any:
    """A value as YAML would read it (``1`` int, ``1.0`` float, ``true`` bool, ``pid`` str).

    YAML 1.1 reads ``3e5`` as a string; a user means the number, so a string
    that parses as a float is one.
    """
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        value = text.strip()
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


def parse_spec(text: str, field: str) -> tuple[str, dict[str, Any]]:
    """``KIND[:key=value,...]`` -> ``(KIND, {key: value})``; ``field`` names the option in errors.

    Refused with one :class:`ParamError` line: an empty kind, an item without
    ``=`` or without a key, and a key given twice.
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
        out[key] = parse_value(value)
    return kind, out
