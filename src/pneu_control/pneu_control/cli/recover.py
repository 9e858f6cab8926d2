"""``pneu recover``: a complete, indexed bag of every readable message of a damaged or cut bag."""

from __future__ import annotations

import argparse

from pneu_msgs_py.bag.recover import recover
from pneu_msgs_py.lifecycle.outputs import PARTIAL, OutputFile, is_same_path

NAME = "recover"
HELP = (
    "copy every readable message of a damaged or cut-short bag (e.g. run.mcap.partial after a "
    "kill) into a complete, indexed bag; says how many messages were lost"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu recover`` options on ``p``."""
    p.add_argument("bag", metavar="BAG", help=".mcap file (or .mcap.partial, rosbag2 directory)")
    p.add_argument("--out", required=True, metavar="NEW.mcap", help="the recovered bag (new)")
    p.add_argument("--overwrite", action="store_true", help="replace NEW.mcap if it exists")


def run(args: argparse.Namespace) -> int:
    """``pneu recover``: write the recovered bag; the exit code."""
    claim = OutputFile(args.out, overwrite=args.overwrite, inputs=[args.bag]).check()
    with claim:
        rep = recover(args.bag, claim.path, partial=claim.partial)
    for w in rep.warnings:
        print(f"warning: {w}")
    print(rep.line())
    if is_same_path(args.bag, claim.path.with_name(claim.path.name + PARTIAL)):
        print(f"kept {args.bag} (the source): remove it once {claim.path} reads as it should")
    return 0
