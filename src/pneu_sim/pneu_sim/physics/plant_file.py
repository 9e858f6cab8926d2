"""``config/plant.yaml``: each leaf ``{value, unit, source}``, loaded strictly into :class:`PlantParams`.

:func:`load_plant` checks each unit string against the field's unit, strips
the leaves to their values and builds :class:`~pneu_sim.physics.params.PlantParams`
with ``from_dict(strict=True)``: a missing key, an unknown key, a wrong type
or a value outside its physical range is refused with one
:class:`~pneu_sim.physics.params.PlantConfigError` naming the key, the value
and the allowed range, and nothing is half-loaded. :func:`dump_plant_yaml`
writes the file back.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pneu_msgs_py.params.core import MISSING, from_dict, to_dict, validate
from pneu_msgs_py.params.paths import config_file
from pneu_msgs_py.params.yaml_file import load_yaml, located

from pneu_sim.physics.params import PlantConfigError, PlantParams

__all__ = ["dump_plant_yaml", "load_plant", "params_from_tree", "plant_to_yaml_tree"]


def _leaf_meta(cls: type) -> dict[str, dataclasses.Field]:
    return {f.name: f for f in dataclasses.fields(cls)}


def _strip(cls: type, tree: Any, prefix: str) -> dict[str, Any]:
    """{value, unit, source} leaves -> values, checking units; structure errors named."""
    if not isinstance(tree, Mapping):
        raise PlantConfigError(prefix.rstrip(".") or "plant", tree, "a mapping of parameters")
    fields = _leaf_meta(cls)
    hints = typing.get_type_hints(cls)
    out: dict[str, Any] = {}
    for key, node in tree.items():
        f = fields.get(key)
        name = f"{prefix}{key}"
        if f is None:
            raise PlantConfigError(name, node, "no such parameter; known: " + ", ".join(fields))
        tp = hints[key]
        if isinstance(tp, type) and dataclasses.is_dataclass(tp):
            out[key] = _strip(tp, node, f"{name}.")
            continue
        if not isinstance(node, Mapping) or "value" not in node:
            raise PlantConfigError(name, node, "a leaf {value: ..., unit: ..., source: ...}")
        extra = set(node) - {"value", "unit", "source"}
        if extra:
            raise PlantConfigError(name, dict(node), "leaf keys value, unit, source only")
        unit = f.metadata.get("unit", "")
        if node.get("unit", "") != unit:
            raise PlantConfigError(f"{name}.unit", node.get("unit"), f"'{unit}'")
        src = node.get("source", "")
        if not isinstance(src, str) or not src.strip():
            raise PlantConfigError(f"{name}.source", src, "a non-empty string naming the source")
        out[key] = node["value"]
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


def params_from_tree(tree: Mapping[str, Any]) -> PlantParams:
    """Build PlantParams from a plant.yaml tree (strict)."""
    return from_dict(PlantParams, _strip(PlantParams, tree, ""), strict=True)


def load_plant(path: str | Path | None = None) -> PlantParams:
    """Load and validate ``plant.yaml`` (default: the project's ``config/plant.yaml``)."""
    path = Path(path) if path is not None else config_file("plant.yaml")
    tree = load_yaml(path)
    with located(path, tree):
        return params_from_tree(tree if tree is not None else {})


def plant_to_yaml_tree(p: Any) -> dict[str, Any]:
    """PlantParams -> {value, unit, source} tree (sources from the field metadata)."""
    out: dict[str, Any] = {}
    values = to_dict(p)
    for f in dataclasses.fields(p):
        v = getattr(p, f.name)
        if dataclasses.is_dataclass(v):
            out[f.name] = plant_to_yaml_tree(v)
        else:
            out[f.name] = {
                "value": values[f.name],
                "unit": f.metadata.get("unit", ""),
                "source": f.metadata.get("source", "") or "-",
            }
    return out


def dump_plant_yaml(p: PlantParams | None = None) -> str:
    """YAML text of ``p`` (default: the built-in values) with a comment per leaf."""
    import yaml

    p = validate(p if p is not None else PlantParams())
    lines = [
        "# Plant of the linear-rotary pneumatic actuator twin (pneu_sim).",
        "# Each leaf: value, unit (must match the code), source (paper table, datasheet,",
        "# or 'estimated: why'). SI units, pressures absolute, except rotary.M_v (N*m/rpm, as",
        "# Table 1). Generated from pneu_sim.physics.params.PlantParams defaults; edit values freely.",
    ]

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

    emit(plant_to_yaml_tree(p), "")
    return "\n".join(lines) + "\n"
