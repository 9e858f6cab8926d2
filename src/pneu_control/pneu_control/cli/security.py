"""``pneu security``: the SROS2 keystore of the graph (enclaves and permissions from the topic table)."""

from __future__ import annotations

import argparse
import os
import re
import sys

from pneu_msgs_py.contract.security import ROLES, operator_enclave
from pneu_msgs_py.params.core import ParamError

NAME = "security"
HELP = (
    "create the SROS2 keystore of the ROS graph: one enclave per node role, permissions from "
    "the topic table (only controllers command valves), the safety services for the named "
    "operators only (needs ROS 2 with sros2)"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu security`` options on ``p``."""
    p.add_argument(
        "keystore", metavar="KEYSTORE", help="keystore directory (new, or one made by this command)"
    )
    p.add_argument(
        "--operator",
        action="append",
        default=[],
        metavar="NAME",
        help="an operator enclave /pneu/operator_NAME: may call ~/estop, ~/reset, the task "
        "runner's ~/start and ~/abort, set parameters and publish trajectories (repeatable)",
    )


# an enclave's certificate carries its path as the subject's common name, which X.509 caps at
# 64 characters (RFC 5280's ub-common-name; cryptography refuses longer): /pneu/operator_NAME
MAX_OPERATOR = 64 - len(operator_enclave("x")) + 1


def run(args: argparse.Namespace) -> int:
    """``pneu security``: the keystore; the exit code."""
    from pneu_msgs_py.lifecycle.outputs import check_writable_dir

    ops = tuple(args.operator)
    for name in ops:
        try:
            operator_enclave(name)
        except ValueError as err:
            raise ParamError(
                "--operator", name, "letters, digits and _, starting with a letter"
            ) from err
        if len(name) > MAX_OPERATOR:
            raise ParamError(
                "--operator",
                f"{name[:12]}... ({len(name)} characters)",
                f"at most {MAX_OPERATOR} characters (the enclave's certificate name, "
                f"{operator_enclave('NAME')}, is at most 64)",
            )
    if len(set(ops)) != len(ops):
        raise ParamError("--operator", ",".join(ops), "each name once")
    domain = os.environ.get("ROS_DOMAIN_ID", "")
    # ASCII digits only: '٣' is a digit to Python (3), not to ROS, nor in the permissions
    if not re.fullmatch(r"[0-9]{1,3}", domain) or not 0 <= int(domain) <= 232:
        raise ParamError(
            "ROS_DOMAIN_ID",
            domain or "(unset)",
            "0-232 in digits 0-9, set: the permissions are bound to the domain",
        )
    if os.path.lexists(args.keystore) and not os.path.isdir(args.keystore):
        raise ParamError("KEYSTORE", args.keystore, "a directory (new, or a keystore)")
    check_writable_dir(args.keystore, "KEYSTORE")  # under a file, read-only, full: now
    if os.path.isdir(args.keystore) and os.listdir(args.keystore):
        if not os.path.exists(os.path.join(args.keystore, "enclaves")):
            raise ParamError(
                "KEYSTORE", args.keystore, "a new directory, or a keystore this command made"
            )
    try:
        from pneu_msgs_py.nodes.security import create
    except ImportError as err:
        print(
            f"pneu security: error: needs ROS 2 with sros2 (source its setup.bash): {err}",
            file=sys.stderr,
        )
        return 1
    made = create(args.keystore, ops)
    print(f"keystore {args.keystore}: {len(made)} enclaves for ROS_DOMAIN_ID {domain}")
    for path in made:
        print(f"  {path}")
    roles = ", ".join(ROLES)
    print(f"launch with keystore:={args.keystore} (roles: {roles})")
    return 0
