"""The ``--live`` options of ``pneu run`` and ``pneu sim``: serve the run to Foxglove while it runs.

Not a subcommand: both commands add these options and open the server with
:func:`open_live` (a :class:`pneu_msgs_py.live.server.LiveServer`, which needs
the optional ``foxglove-sdk`` package; without it, one error line).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable
from typing import Any

from pneu_msgs_py.live import PACES
from pneu_msgs_py.live.server import DEFAULT_PORT  # foxglove is imported when a server starts
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.spec import parse_number

DEFAULT_HOST = "127.0.0.1"

__all__ = ["add_arguments", "open_live"]


def _port(text: str) -> int:
    try:
        v = parse_number(text, int)  # as typed: 8_765 is not 8765
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    if not 0 <= v <= 65535:
        raise argparse.ArgumentTypeError(f"{v} outside 0 (any free port) to 65535")
    return v


def _wait(text: str) -> float:
    try:
        v = parse_number(text, float)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    if not 0.0 <= v <= 3600.0:
        raise argparse.ArgumentTypeError(f"{v:g} s outside [0, 3600] s")
    return v


def add_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("live view (Foxglove app over WebSocket; needs foxglove-sdk)")
    g.add_argument(
        "--live",
        nargs="?",
        const=DEFAULT_PORT,
        default=None,
        type=_port,
        metavar="PORT",
        help=f"serve the run to Foxglove while it runs, on the bag's topics (port default "
        f"{DEFAULT_PORT}; 0 = any free port); the ws:// URL is printed",
    )
    g.add_argument(
        "--live-host",
        default=None,
        metavar="HOST",
        help="with --live: interface to serve on (default 127.0.0.1: this machine; 0.0.0.0: "
        "every interface)",
    )
    g.add_argument(
        "--live-pace",
        choices=PACES,
        default=None,
        help="with --live: realtime: simulated time advances with the wall clock (default); "
        "fast: as fast as the run goes",
    )
    g.add_argument(
        "--live-wait",
        type=_wait,
        default=None,
        metavar="S",
        help="with --live: wait up to S seconds for a viewer to subscribe before the run starts "
        "(default 0: start at once; messages sent before a viewer subscribes are not kept)",
    )


def open_live(
    args: argparse.Namespace, *, axes: Iterable[str], kind: str, controller_state: bool = True
) -> Any:
    """The live server the options ask for (None without ``--live``); prints its URL on stderr.

    ``kind``: ``linear`` | ``rotary`` | ``both``, the Foxglove layout to suggest.
    """
    given = [o for o, v in (("--live-host", args.live_host), ("--live-pace", args.live_pace),
                            ("--live-wait", args.live_wait)) if v is not None]  # fmt: skip
    if args.live is None:
        if given:  # an option of the live view without one would be silently ignored
            raise ParamError(
                given[0], getattr(args, given[0][2:].replace("-", "_")), "only with --live"
            )
        return None
    host = args.live_host if args.live_host is not None else DEFAULT_HOST
    pace = args.live_pace if args.live_pace is not None else "realtime"
    wait = args.live_wait if args.live_wait is not None else 0.0
    from pneu_msgs_py.live.server import LiveServer
    from pneu_msgs_py.params.paths import config_dir

    server = LiveServer(
        axes=axes,
        port=args.live,
        host=host,
        pace=pace,
        controller_state=controller_state,
    )
    layout = config_dir() / "layouts" / f"foxglove_{kind}.json"
    print(
        f"live view: {server.url} ({pace}) -- Foxglove: Open connection > "
        f"Foxglove WebSocket; layout: {layout}",
        file=sys.stderr,
        flush=True,
    )
    if wait > 0:
        print(
            f"live view: waiting up to {wait:g} s for a viewer",
            file=sys.stderr,
            flush=True,
        )
        if not server.wait_for_viewer(wait):
            print("live view: no viewer yet; starting the run", file=sys.stderr, flush=True)
    return server
