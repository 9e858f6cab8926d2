"""``python -m pneu_driver.cli.probe``: is the rig's DAQ device there? (no ROS, no task created)

Prints the device and the devices visible and exits 0 when the configured
device is present; otherwise one line on stderr naming the device and listing
what is visible, exit 1. The driver node makes the same check when it opens.
"""

from __future__ import annotations

import argparse
import sys

from pneu_msgs_py.params.core import ParamError

from pneu_driver.daq.errors import DriverError
from pneu_driver.daq.nidaqmx_backend import visible_devices
from pneu_driver.daq.rig import load_rig_params

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m pneu_driver.cli.probe", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--rig", help="rig.yaml (default: the project's config/rig.yaml)")
    parser.add_argument("--device", help="device name, overriding rig.yaml")
    args = parser.parse_args(argv)
    try:
        rig = load_rig_params(args.rig)
        device = args.device or rig.device
        names = visible_devices(device)
    except (DriverError, ParamError, OSError) as err:
        print(f"pneu_driver: error: {err}", file=sys.stderr)
        return 1
    if device not in names:
        seen = ", ".join(names) or "none"
        print(
            f"pneu_driver: error: DAQ device {device!r} not found; devices visible: {seen}",
            file=sys.stderr,
        )
        return 1
    print(f"{device}: present (devices visible: {', '.join(names)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
