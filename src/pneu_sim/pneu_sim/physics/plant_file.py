"""``config/plant.yaml``: each leaf ``{value, unit, source}``, loaded strictly into :class:`PlantParams`.

:func:`load_plant` checks each unit string against the field's unit, strips
the leaves to their values and builds :class:`~pneu_sim.physics.params.PlantParams`
with ``from_dict(strict=True)``: a missing key, an unknown key, a wrong type
or a value outside its physical range is refused with one
:class:`~pneu_sim.physics.params.PlantConfigError` naming the key, the value
and the allowed range, and nothing is half-loaded. :func:`dump_plant_yaml`
writes the file back.

An uncertain leaf may also carry ``range: [lo, hi]`` or ``alternatives:
{label: value, ...}`` (:mod:`pneu_sim.physics.ranges`; both optional, so files
without them load as before). :func:`load_plant_file` returns them with the
parameters; :func:`dump_plant_yaml` writes them (by default the table's).
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pneu_msgs_py.params.core import MISSING, from_dict, to_dict, unknown_key, validate
from pneu_msgs_py.params.paths import config_file
from pneu_msgs_py.params.yaml_file import load_yaml, located

from pneu_sim.physics.params import PlantConfigError, PlantParams
from pneu_sim.physics.ranges import PlantRanges, check_alternatives, check_range, table_ranges

__all__ = [
    "dump_plant_yaml",
    "load_plant",
    "load_plant_file",
    "params_from_tree",
    "plant_from_tree",
    "plant_to_yaml_tree",
    "plant_tree_yaml",
]

_LEAF_KEYS = ("value", "unit", "source", "range", "alternatives")


def _leaf_meta(cls: type) -> dict[str, dataclasses.Field]:
    return {f.name: f for f in dataclasses.fields(cls)}


def _strip(cls: type, tree: Any, prefix: str, unc: PlantRanges) -> dict[str, Any]:
    """{value, unit, source[, range | alternatives]} leaves -> values, checking units;
    structure errors named; ranges and alternatives checked into ``unc``."""
    if not isinstance(tree, Mapping):
        raise PlantConfigError(prefix.rstrip(".") or "plant", tree, "a mapping of parameters")
    fields = _leaf_meta(cls)
    hints = typing.get_type_hints(cls)
    out: dict[str, Any] = {}
    for key, node in tree.items():
        f = fields.get(key)
        name = f"{prefix}{key}"
        if f is None:
            raise PlantConfigError(name, node, unknown_key(key, fields))
        tp = hints[key]
        if isinstance(tp, type) and dataclasses.is_dataclass(tp):
            out[key] = _strip(tp, node, f"{name}.", unc)
            continue
        if not isinstance(node, Mapping) or "value" not in node:
            raise PlantConfigError(name, node, "a leaf {value: ..., unit: ..., source: ...}")
        extra = set(node) - set(_LEAF_KEYS)
        if extra:
            raise PlantConfigError(name, dict(node), "leaf keys " + ", ".join(_LEAF_KEYS) + " only")
        unit = f.metadata.get("unit", "")
        if node.get("unit", "") != unit:
            raise PlantConfigError(f"{name}.unit", node.get("unit"), f"'{unit}'")
        src = node.get("source", "")
        if not isinstance(src, str) or not src.strip():
            raise PlantConfigError(f"{name}.source", src, "a non-empty string naming the source")
        out[key] = node["value"]
        for extra_key in ("range", "alternatives"):
            if extra_key in node and tp is not float:
                raise PlantConfigError(
                    f"{name}.{extra_key}", node[extra_key], "none: only real-valued parameters vary"
                )
        if "range" in node:
            unc.ranges[name] = check_range(name, node["value"], node["range"], f.metadata)
        if "alternatives" in node:
            unc.alternatives[name] = check_alternatives(
                name, node["value"], node["alternatives"], f.metadata
            )
    for key, f in fields.items():
        if key not in out:
            tp = hints[key]
            if isinstance(tp, type) and dataclasses.is_dataclass(tp):
                need = "the parameter group " + ", ".join(_leaf_meta(tp))
            else:
                unit = f.metadata.get("unit", "")
                need = f"a leaf {{value, unit: '{unit}', source}}"
            raise PlantConfigError(f"{prefix}{key}", MISSING, need)
    return out


def plant_from_tree(tree: Mapping[str, Any]) -> tuple[PlantParams, PlantRanges]:
    """PlantParams and the ranges/alternatives of a plant.yaml tree (strict)."""
    unc = PlantRanges()
    params = from_dict(PlantParams, _strip(PlantParams, tree, "", unc), strict=True)
    return params, unc


def params_from_tree(tree: Mapping[str, Any]) -> PlantParams:
    """Build PlantParams from a plant.yaml tree (strict)."""
    return plant_from_tree(tree)[0]


def load_plant(path: str | Path | None = None) -> PlantParams:
    """Load and validate ``plant.yaml`` (default: the project's ``config/plant.yaml``)."""
    return load_plant_file(path)[0]


def load_plant_file(path: str | Path | None = None) -> tuple[PlantParams, PlantRanges]:
    """``plant.yaml`` (default: the project's) -> (parameters, their ranges/alternatives)."""
    path = Path(path) if path is not None else config_file("plant.yaml")
    tree = load_yaml(path)
    with located(path, tree):
        return plant_from_tree(tree if tree is not None else {})


def plant_to_yaml_tree(
    p: Any, ranges: PlantRanges | None = None, prefix: str = ""
) -> dict[str, Any]:
    """PlantParams -> {value, unit, source[, range | alternatives]} tree (sources from
    the field metadata; ``ranges`` default: none)."""
    unc = ranges if ranges is not None else PlantRanges()
    out: dict[str, Any] = {}
    values = to_dict(p)
    for f in dataclasses.fields(p):
        v = getattr(p, f.name)
        name = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(v):
            out[f.name] = plant_to_yaml_tree(v, unc, f"{name}.")
            continue
        leaf = {
            "value": values[f.name],
            "unit": f.metadata.get("unit", ""),
            "source": f.metadata.get("source", "") or "-",
        }
        if name in unc.ranges:
            leaf["range"] = list(unc.ranges[name])
        if name in unc.alternatives:
            leaf["alternatives"] = dict(unc.alternatives[name])
        out[f.name] = leaf
    return out


def dump_plant_yaml(p: PlantParams | None = None, ranges: PlantRanges | None = None) -> str:
    """YAML text of ``p`` (default: the built-in values) with a comment per leaf.

    ``ranges``: the ranges/alternatives to write (default: the table's,
    :func:`pneu_sim.physics.ranges.table_ranges` for the values of ``p``); checked
    like a loaded file's, so the text always loads back.
    """
    p = validate(p if p is not None else PlantParams())
    unc = ranges if ranges is not None else table_ranges(p)
    header = [
        "# Plant of the linear-rotary pneumatic actuator twin (pneu_sim).",
        "# Each leaf: value, unit (must match the code), source (paper table, datasheet,",
        "# or 'estimated: why'). SI units, pressures absolute, except rotary.M_v (N*m/rpm, as",
        "# Table 1). Uncertain values also carry range: [lo, hi] or alternatives: {label: value}",
        "# (what pneu sweep draws from). Generated from pneu_sim.physics.params.PlantParams",
        "# defaults; edit values freely.",
    ]
    tree = plant_to_yaml_tree(p, unc)
    plant_from_tree(tree)  # the same checks as loading: what is written loads back
    return plant_tree_yaml(tree, header)


def plant_tree_yaml(tree: Mapping[str, Any], header: list[str]) -> str:
    """YAML text of a plant.yaml tree: ``header`` comment lines, then one flow-style line
    per leaf (every key of a leaf kept, in its order)."""
    import yaml

    lines = list(header)

    def emit(tree: Mapping[str, Any], indent: str) -> None:
        for key, node in tree.items():
            if "value" in node and isinstance(node.get("unit"), str):
                leaf = yaml.safe_dump(
                    dict(node),
                    default_flow_style=True,
                    allow_unicode=True,
                    width=10_000,
                    sort_keys=False,
                ).strip()
                lines.append(f"{indent}{key}: {leaf}")
            else:
                lines.append(f"{indent}{key}:")
                emit(node, indent + "  ")

    emit(tree, "")
    return "\n".join(lines) + "\n"
