"""``pneu``: the user's command line. One subcommand per module.

Each subcommand module exposes ``NAME``, ``HELP``, ``add_arguments(parser)``
and ``run(args) -> int``. Errors reach the user as one line on stderr, never
a traceback, with the exit codes of :mod:`pneu_msgs_py.lifecycle.exits`:
0 success, 1 runtime error, 2 bad input (``ParamError``, ``BagError``,
refused options), 3 the supervisor took an axis safe, 128 + N interrupted by
signal N (SIGHUP 129, SIGINT 130, SIGTERM 143).
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import re
import signal
import sys
import warnings
from typing import NoReturn

from pneu_msgs_py.lifecycle import exits, signals

__all__ = ["main", "SUBCOMMANDS"]

# (subcommand, module) -- modules are imported lazily so one missing optional
# dependency never breaks the others.
SUBCOMMANDS: tuple[tuple[str, str], ...] = (
    ("sim", "pneu_sim.cli.sim"),
    ("run", "pneu_control.cli.run"),
    ("task", "pneu_control.cli.task"),
    ("rig", "pneu_control.cli.rig"),
    ("paper", "pneu_control.cli.paper"),
    ("sweep", "pneu_control.cli.sweep"),
    ("analyze", "pneu_control.cli.analyze"),
    ("plot", "pneu_control.cli.plot"),
    ("compare", "pneu_control.cli.compare"),
    ("replay", "pneu_control.cli.replay"),
    ("recover", "pneu_control.cli.recover"),
    ("tune", "pneu_control.cli.tune"),
    ("excite", "pneu_control.cli.excite"),
    ("identify", "pneu_control.cli.identify"),
    ("validate", "pneu_control.cli.validate"),
    ("bench", "pneu_control.cli.bench"),
    ("security", "pneu_control.cli.security"),
)


class UserError(Exception):
    """An error the user can fix; printed as one line (exit 2)."""


_NEGATIVE = re.compile(
    r"^-(?:[0-9][0-9_:]*\.?[0-9_]*|\.[0-9][0-9_]*)(?:e[-+]?[0-9]+)?$"
    r"|^-(?:inf|infinity|nan|\.inf|0x[0-9a-f]+|0o[0-7]+)$",
    re.IGNORECASE,
)
_REPEATABLE = (argparse._AppendAction, argparse._CountAction, argparse._ExtendAction)


def _number_as_typed(text: str, want: type) -> float | int:
    """A number as the config files read it (``010`` 10, ``0x10`` 16, ``3e5``); ``1_000`` and
    ``1:00`` are not numbers (Python's ``float`` would read 1000; YAML 1.1 60)."""
    from pneu_msgs_py.params.spec import parse_number

    try:
        return parse_number(text, want)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


class _Parser(argparse.ArgumentParser):
    """argparse with one-line refusals: ``pneu run: error: argument --duration: ...`` (exit 2),
    and numbers read as typed (``type=float``/``type=int`` options, docs/cli.md)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        # a value that reads as a negative number is a value, not an option: argparse's own
        # rule takes only -5 and -.5 ('--duration -inf' or '-1e3': "expected one argument")
        self._negative_number_matcher = _NEGATIVE
        self.register("type", float, lambda t: _number_as_typed(t, float))
        self.register("type", int, lambda t: _number_as_typed(t, int))

    def parse_known_args(self, args=None, namespace=None):
        self._given: dict[str, str] = {}  # dest -> the option that set it (each once)
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> NoReturn:
        self.exit(
            exits.BAD_INPUT,
            f"{self.prog}: error: {_one_line(message)} (see {self.prog} --help)\n",
        )

    def _get_values(self, action, arg_strings):
        # an empty value is never meant: '' as --out would be '.', as --plant the default file,
        # as --reference the file's reference (docs/cli.md: an option given is never empty)
        own = action.nargs not in (argparse.PARSER, argparse.REMAINDER)  # not a subcommand's
        for text in arg_strings if own and isinstance(arg_strings, list) else ():
            if isinstance(text, str) and not text.strip():
                name = "/".join(action.option_strings) or action.metavar or action.dest
                self.error(f"argument {name}: {text!r} refused; allowed: a value that is not empty")
        if own and action.option_strings and not isinstance(action, _REPEATABLE):
            # given twice, the last would silently win (--duration 1 ... --duration 600)
            given = self.__dict__.setdefault("_given", {})
            values = " ".join(map(repr, arg_strings)) if isinstance(arg_strings, list) else ""
            if action.dest in given:
                name = "/".join(action.option_strings)
                twice = f" ({given[action.dest]}, then {values})" if values else ""
                self.error(
                    f"argument {name}: given twice{twice}; allowed: each option once "
                    "(only the options that say so repeat, e.g. --set)"
                )
            given[action.dest] = values
        return super()._get_values(action, arg_strings)

    def parse_args(self, args=None, namespace=None):
        # an argument nobody takes is refused by the subcommand it was given to (argparse's own
        # line says "pneu: error:" whatever the subcommand), with the option it resembles
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            sub = getattr(self, "commands", {}).get(getattr(ns, "command", None), self)
            sub.error(f"unrecognized arguments: {' '.join(extras)}{_close_option(extras, sub)}")
        return ns


def _close_option(extras: list[str], parser: argparse.ArgumentParser) -> str:
    """``; did you mean --duration?`` for the first extra that resembles an option of ``parser``
    (a typo, an abbreviation that fits none, a dash turned into a typographic one)."""
    import difflib

    known = [o for a in parser._actions for o in a.option_strings if o.startswith("--")]
    for text in extras:
        word = re.sub(r"^[\u2010-\u2015\u2212-]+", "--", text.split("=", 1)[0])
        close = difflib.get_close_matches(word, known, n=1, cutoff=0.7)
        given = text.split("=", 1)[0]
        opposite = close and close[0] == "--" + word.removeprefix("--no-")  # --no-X is not --X
        if word.startswith("--") and close and given not in known and not opposite:
            return f"; did you mean {close[0]}?"
    return ""


class _PipeSafe:
    """stdout whose reader may go away (``| head``): what is written after is dropped and the
    command goes on, so its files are finished and its exit code is its own (a supervisor stop
    stays 3)."""

    def __init__(self, stream) -> None:
        self._s = stream

    def write(self, text: str) -> int:
        try:
            return self._s.write(text)
        except BrokenPipeError:
            self._drop()
            return len(text)

    def flush(self) -> None:
        try:
            self._s.flush()
        except BrokenPipeError:
            self._drop()

    def _drop(self) -> None:
        try:  # the descriptor onto /dev/null: the stream's last flush, at exit, succeeds too
            fd = os.open(os.devnull, os.O_WRONLY)
            os.dup2(fd, self._s.fileno())
            os.close(fd)
        except (OSError, ValueError, AttributeError):
            self._s = open(os.devnull, "w")  # kept for the command's life

    def __getattr__(self, name: str):
        return getattr(self._s, name)


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
    """The ``pneu`` parser with one subcommand per module of :data:`SUBCOMMANDS`."""
    parser = _Parser(
        prog="pneu",
        description="pneu: servo stack for a linear-rotary pneumatic actuator (twin, controllers, bags).",
        epilog="exit codes: "
        + "; ".join(f"{code} {text.split(':')[0]}" for code, text in exits.EXIT_CODES),
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    parser.commands = {}
    for name, mod in _available():
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
        parser.commands[name] = p
    return parser


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"pneu: warning: {_one_line(str(message))}", file=sys.stderr)


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def main(argv: list[str] | None = None, *, restore_signals: bool = True) -> int:
    """Run one subcommand; return its exit code (docs/cli.md: 0, 1, 2, 3, 129, 130, 143).

    ``restore_signals`` False (the ``pneu`` process itself): after the command, signals
    stay recorded-only, so one arriving while the interpreter shuts down changes nothing.
    """
    from pneu_msgs_py.params import inputs

    restore = signals.install()  # first: a signal at any moment from here on ends cleanly
    stdout = sys.stdout
    if stdout is not None:  # None: started with stdout closed (nothing is printed then)
        sys.stdout = _PipeSafe(stdout)
    try:
        with inputs.tracking():  # every file the command reads: never one of its outputs
            return _main(argv)
    except signals.Interrupted as err:  # during argument parsing or set-up
        print(f"pneu: interrupted by {signals.signal_name(err.signum)}", file=sys.stderr)
        return exits.interrupted_code(err.signum)
    finally:
        if isinstance(sys.stdout, _PipeSafe):
            sys.stdout.flush()
            sys.stdout = stdout
        if restore_signals:
            restore()
        else:
            signals.STATE.defer += 1  # from here to the exit: record, never raise


def cli() -> NoReturn:
    """The ``pneu`` console script."""
    code = main(restore_signals=False)
    # the command is done and its files are finished: a signal from here to the exit is
    # ignored (Python's shutdown would reset a Python handler to the default, which kills)
    for s in signals.SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    sys.exit(code)


def _main(argv: list[str] | None) -> int:
    warnings.showwarning = _show_warning  # one line per warning, no source echo
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # --help (0) or a refused option (2, one line printed)
        return int(exit_.code or 0) if not isinstance(exit_.code, str) else exits.BAD_INPUT
    name = f"pneu {args.command}"
    try:
        code = int(args._run(args) or 0)
    except signals.Interrupted as err:
        print(
            f"{name}: interrupted by {signals.signal_name(err.signum)}; "
            "no output was left half-written",
            file=sys.stderr,
        )
        return exits.interrupted_code(err.signum)
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        return exits.interrupted_code(signal.SIGINT)
    except BrokenPipeError:  # stdout closed early (| head), written past _PipeSafe: not ours
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return exits.OK
    except Exception as err:
        if os.environ.get("PNEU_DEBUG"):
            raise
        code, text = _classify(err)
        print(f"{name}: error: {_one_line(text)}", file=sys.stderr)
        return code
    sig = signals.pending()
    if sig is not None and code in (exits.OK, exits.SAFETY_STOP):
        return exits.interrupted_code(sig)
    return code


def _classify(err: Exception) -> tuple[int, str]:
    """(exit code, one line) for an exception that reached the command line."""
    from pneu_msgs_py.bag.errors import BagError, BagWriteError
    from pneu_msgs_py.live.errors import LiveError
    from pneu_msgs_py.params.core import ParamError

    if isinstance(err, (BagWriteError, exits.CommandFailed)):
        return exits.RUNTIME_ERROR, str(err)
    if isinstance(err, (ParamError, BagError, LiveError, UserError)):
        return exits.BAD_INPUT, str(err)
    if isinstance(err, ValueError) and _raised_by_pneu(err):  # our checks refuse a value
        return exits.BAD_INPUT, str(err)
    if isinstance(err, OSError):
        where = f"{err.filename}: " if err.filename else ""
        full = err.errno in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT)
        why = " (writing the outputs: a full disk or a file-size limit)" if full else ""
        return exits.RUNTIME_ERROR, f"{where}{err.strerror or err}{why}"
    if isinstance(err, MemoryError):
        return exits.RUNTIME_ERROR, "out of memory"
    return (
        exits.RUNTIME_ERROR,
        f"internal error ({type(err).__name__}: {err}); please report it "
        "(PNEU_DEBUG=1 shows the traceback)",
    )


def _raised_by_pneu(err: Exception) -> bool:
    """Was ``err`` raised in the project's own code (a refusal), not inside numpy & co (a bug)?"""
    tb = err.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    where = tb.tb_frame.f_code.co_filename if tb is not None else ""
    return any(
        f"{pkg}{os.sep}" in where
        for pkg in ("pneu_control", "pneu_sim", "pneu_msgs_py", "pneu_driver")
    )


if __name__ == "__main__":
    cli()
