"""``pneu``: the user's command line. One subcommand per module.

Each subcommand module exposes ``NAME``, ``HELP``, ``add_arguments(parser)``
and ``run(args) -> int``. User errors (bad config, bad option values, bad
files) reach the user as one line on stderr and a non-zero exit, never a
traceback.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings

__all__ = ["main", "SUBCOMMANDS"]

# (subcommand, module) -- modules are imported lazily so one missing optional
# dependency never breaks the others.
SUBCOMMANDS: tuple[tuple[str, str], ...] = (
    ("sim", "pneu_sim.cli.sim"),
    ("run", "pneu_control.cli.run"),
    ("rig", "pneu_control.cli.rig"),
    ("paper", "pneu_control.cli.paper"),
    ("sweep", "pneu_control.cli.sweep"),
    ("analyze", "pneu_control.cli.analyze"),
    ("plot", "pneu_control.cli.plot"),
    ("compare", "pneu_control.cli.compare"),
    ("replay", "pneu_control.cli.replay"),
    ("tune", "pneu_control.cli.tune"),
    ("excite", "pneu_control.cli.excite"),
    ("identify", "pneu_control.cli.identify"),
    ("validate", "pneu_control.cli.validate"),
    ("bench", "pneu_control.cli.bench"),
)


class UserError(Exception):
    """An error the user can fix; printed as one line."""


def _available() -> list[tuple[str, object]]:
    mods = []
    for name, modname in SUBCOMMANDS:
        try:
            mods.append((name, importlib.import_module(modname)))
        except ModuleNotFoundError as err:
            if err.name and (err.name == modname or modname.startswith(err.name + ".")):
                continue  # subcommand not built yet
            raise
    return mods


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pneu",
        description="pneu: servo stack for a linear-rotary pneumatic actuator (twin, controllers, bags).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, mod in _available():
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"pneu: warning: {message}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    warnings.showwarning = _show_warning  # one line per warning, no source echo
    parser = build_parser()
    args = parser.parse_args(argv)  # argparse exits 2 with a usage line on bad options
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print("pneu: interrupted", file=sys.stderr)
        return 130
    except Exception as err:
        if not _is_user_error(err) or os.environ.get("PNEU_DEBUG"):
            raise
        print(f"pneu {args.command}: error: {err}", file=sys.stderr)
        return 1


def _is_user_error(err: Exception) -> bool:
    """Errors a user can fix (bad config, option, file) -> one line, no traceback."""
    from pneu_msgs_py.bag.errors import BagError
    from pneu_msgs_py.live.errors import LiveError
    from pneu_msgs_py.params.core import ParamError

    return isinstance(err, (ParamError, BagError, LiveError, UserError, OSError, ValueError))


if __name__ == "__main__":
    sys.exit(main())
