"""Where the project's config files are, with or without ROS."""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["config_dir", "config_file"]

_PACKAGES = ("pneu_control", "pneu_sim", "pneu_driver", "pneu_msgs_py")


def config_dir() -> Path:
    """The directory holding plant.yaml, controllers.yaml, rig.yaml, safety.yaml.

    Order: ``$PNEU_CONFIG_DIR``; the source tree's ``config/`` (editable
    install); ``share/<pkg>/config`` of an installed package (colcon or pip).
    """
    env = os.environ.get("PNEU_CONFIG_DIR")
    if env:
        return Path(env)
    here = Path(__file__).resolve()
    for parent in here.parents:
        cand = parent / "config" / "plant.yaml"
        if cand.is_file() and (parent / "src").is_dir():
            return parent / "config"
    prefixes = [Path(sys.prefix)]
    prefixes += [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for prefix in prefixes:
        for pkg in _PACKAGES:
            cand = prefix / "share" / pkg / "config"
            if (cand / "plant.yaml").is_file():
                return cand
    raise FileNotFoundError(
        "pneu config directory not found: set PNEU_CONFIG_DIR or install the packages"
    )


def config_file(name: str) -> Path:
    return config_dir() / name
