"""One ``main()`` for every node: rclpy init, executor, spin, Ctrl-C, a safe shutdown.

Every node shell of the project implements :class:`NodeShell` and its
console-script entry is ``run_node("<name>", MakeNode)``. What this does, in
the Jazzy shape (ros2/demos ``talker.py``) plus what a rig needs:

1. ``rclpy.init``; the node is built (a bad parameter or file ends here with
   one line and exit status 1);
2. the executor: :data:`EXECUTORS` ``events`` (``rclpy.experimental.
   EventsExecutor``, rclpy >= 7.1.4), ``single`` (``SingleThreadedExecutor``)
   or ``auto`` (events where this rclpy has it). Chosen by the node's
   ``executor`` parameter if it declares one, else the environment variable
   ``PNEU_EXECUTOR``, else the node's default;
3. with a node's ``process_rt_priority`` > 0, every thread of the process (the executor,
   the DDS threads; the loop and publishing threads that ``start`` creates inherit it) at
   SCHED_FIFO that priority and its memory locked -- or one warning line saying what could
   not be set, what that costs and how to grant it (:mod:`pneu_msgs_py.lifecycle.realtime`);
   ``node.start()``, then spin until ``node.done`` (a Future, or forever when
   None), Ctrl-C or an external shutdown (SIGTERM) -- in slices of
   :data:`SPIN_SLICE_S`, so that a signal is always seen. Once spinning, a SIGINT
   only asks the spin to end (:class:`_StopRequest`): Python's own handler raised
   KeyboardInterrupt wherever the main thread was, most often inside a sample's
   callback at 1 kHz, which the EventsExecutor reported as a FATAL "Exception in
   'subscriptions' callback" with a stack on every Ctrl-C;
4. always: the executor is shut down (EventsExecutor must stop before its
   nodes go), ``node.safe_shutdown()`` leaves the rig safe and files complete
   -- with a second SIGINT ignored meanwhile (under ``ros2 launch`` a Ctrl-C
   can reach a node twice) -- then the node is destroyed and rclpy shut down. In a
   node's own process (its console script, :func:`node_entry`) SIGINT stays ignored from
   then on: a node that ended by itself as ``ros2 launch`` ends the run gets launch's
   SIGINT while the interpreter exits, and a KeyboardInterrupt there kills the process
   by the signal (launch: "process has died, exit code -2" after a clean run).

rclpy is imported inside the functions: this module imports without ROS.
"""

from __future__ import annotations

import gc
import os
import signal
import sys
from collections.abc import Callable, Sequence
from typing import Any, Protocol

__all__ = [
    "EXECUTORS",
    "EXECUTOR_ENV",
    "NodeShell",
    "ShellDefaults",
    "executor_kind",
    "make_executor",
    "node_entry",
    "run_node",
]

EXECUTORS = ("auto", "events", "single")
SPIN_SLICE_S = 0.25
EXECUTOR_ENV = "PNEU_EXECUTOR"


class NodeShell(Protocol):
    """What :func:`run_node` needs of a node (besides being an ``rclpy.node.Node``)."""

    default_executor: str  # one of EXECUTORS: what works and measures best for this node
    done: Any  # an rclpy Future to spin until, or None: spin until stopped
    process_rt_priority: int  # > 0: every thread of the process at SCHED_FIFO this (DESIGN §10)

    def start(self) -> None:
        """Called once the executor is ready, before spinning (start threads, timers)."""

    def safe_shutdown(self) -> None:
        """Leave the rig safe (valves at 5 V) and every file complete; must not raise."""

    def exit_code(self) -> int:
        """0, or 1 when the node stopped on an error of its own (already reported)."""


class ShellDefaults:
    """Mix-in with the :class:`NodeShell` defaults: spin until stopped, nothing to start."""

    default_executor = "auto"
    done: Any = None
    process_rt_priority = 0

    def start(self) -> None:
        pass

    def exit_code(self) -> int:
        return 0


def executor_kind(node: Any, default: str = "auto") -> str:
    """The executor asked for: parameter ``executor`` > ``$PNEU_EXECUTOR`` > ``default``.

    Declares the read-only string parameter ``executor`` on ``node`` (every
    node has it: ``ros2 run pneu_sim sim_node --ros-args -p executor:=single``).
    """
    from rcl_interfaces.msg import ParameterDescriptor

    if not node.has_parameter("executor"):
        node.declare_parameter(
            "executor",
            "",
            ParameterDescriptor(
                description="rclpy executor: events, single or auto ('' = $PNEU_EXECUTOR, "
                f"else this node's default, {default})",
                additional_constraints="one of '', " + ", ".join(EXECUTORS),
                read_only=True,
            ),
        )
    kind = str(node.get_parameter("executor").value or "")
    kind = kind or os.environ.get(EXECUTOR_ENV, "") or default
    if kind not in EXECUTORS:
        raise ValueError(f"executor: {kind!r} refused; allowed: one of {', '.join(EXECUTORS)}")
    return kind


def make_executor(kind: str) -> tuple[Any, str]:
    """(executor, the kind actually used) for ``kind`` in :data:`EXECUTORS`."""
    if kind not in EXECUTORS:
        raise ValueError(f"executor: {kind!r} refused; allowed: one of {', '.join(EXECUTORS)}")
    if kind in ("auto", "events"):
        try:
            from rclpy.experimental import EventsExecutor
        except ImportError:
            if kind == "events":
                raise ValueError(
                    "executor: 'events' refused; this rclpy has no rclpy.experimental."
                    "EventsExecutor (Jazzy rclpy >= 7.1.4); allowed: single, auto"
                ) from None
        else:
            return EventsExecutor(), "events"
    from rclpy.executors import SingleThreadedExecutor

    return SingleThreadedExecutor(), "single"


# set by node_entry: this process is the node's own (module docstring, step 4)
_OWN_PROCESS = False


def node_entry(module: str, func: str = "main") -> Callable[..., int]:
    """A console script's main that imports the node's ``module`` under a Ctrl-C guard.

    Importing a node takes seconds on a busy machine (numba, rclpy, the cores): a Ctrl-C
    (``ros2 launch``'s SIGINT) that lands then ends the process cleanly, with exit status
    0 and no traceback -- nothing has started, there is nothing to make safe. After the
    import :func:`run_node` handles every signal.
    """

    def main(args: list[str] | None = None) -> int:
        import importlib

        try:
            target = getattr(importlib.import_module(module), func)
        except KeyboardInterrupt:
            return 0
        global _OWN_PROCESS
        _OWN_PROCESS = True
        return target(args)

    main.__name__ = main.__qualname__ = f"{module.rsplit('.', 1)[-1]}_{func}"
    return main


def _before_init(name: str, args: list[str] | None) -> None:
    """The process's enclave with security on (DESIGN §13); the sim on localhost-only
    discovery unless the user chose a range (a twin has no business on the lab network)."""
    from pneu_msgs_py.contract.security import select_enclave

    select_enclave(name, os.environ, list(sys.argv if args is None else args))
    if name == "sim_node":
        os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


def _realtime(node: Any, priority: int) -> None:
    """Step 3's realtime settings for the whole process, said in the node's log."""
    from pneu_msgs_py.lifecycle.realtime import realtime_process

    notes, missing = realtime_process(priority)
    if notes:
        node.get_logger().info("realtime: " + "; ".join(notes))
    if missing:
        node.get_logger().warning(missing)


class _StopRequest:
    """SIGINT while spinning: remembered (``bool(self)``), never raised into a callback; the
    spin loop sees it within :data:`SPIN_SLICE_S`. Restores the previous handler on exit."""

    def __init__(self) -> None:
        self.signum = 0
        try:
            self.previous = signal.signal(signal.SIGINT, self._on_signal)
        except ValueError:  # not the main thread: signals are not ours to handle
            self.previous = None
            self.restore = lambda: None

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.signum = signum

    def __bool__(self) -> bool:
        return bool(self.signum)

    def restore(self) -> None:
        signal.signal(signal.SIGINT, self.previous or signal.default_int_handler)


def run_node(name: str, make_node: Callable[[], NodeShell], args: list[str] | None = None) -> int:
    """Run one node to the end (see the module docstring); returns the exit status."""
    import rclpy
    from rclpy.exceptions import ParameterException
    from rclpy.executors import ExternalShutdownException
    from rclpy.task import Future

    from pneu_msgs_py.params.core import ParamError

    nodes: list[NodeShell] = []
    node = executor = None
    code = 0
    try:
        _before_init(name, args)
        rclpy.init(args=args)
        made = make_node()
        nodes = list(made) if isinstance(made, Sequence) else [made]
        node = nodes[0]
        executor, used = make_executor(executor_kind(node, node.default_executor))
        node.get_logger().info(f"executor: {used}")
        for n in nodes:
            executor.add_node(n)
        # what start-up made (rclpy, numpy, the cores: every object alive now) leaves the cyclic
        # collector, so a full collection at a random callback does not walk it all
        # (milliseconds; the realtime loops do the same: pneu_msgs_py.lifecycle.realtime)
        gc.collect()
        gc.freeze()
        _realtime(node, max(n.process_rt_priority for n in nodes))
        for n in nodes:
            n.start()
        # Spin in slices: Python gets control back every SPIN_SLICE_S, so Ctrl-C and SIGTERM
        # always end the spin (measured on rclpy 7.1.9: an EventsExecutor that only has slow
        # timers sometimes sat out a SIGINT until launch escalated to SIGTERM).
        done = node.done if node.done is not None else Future()
        stop = _StopRequest()
        try:
            while rclpy.ok() and not done.done() and not stop:
                executor.spin_until_future_complete(done, timeout_sec=SPIN_SLICE_S)
        finally:
            stop.restore()
        code = node.exit_code()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ParamError, ParameterException, OSError, ValueError, RuntimeError) as err:
        print(f"{name}: error: {err}", file=sys.stderr)
        code = 1
    finally:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            if executor is not None:
                try:
                    executor.shutdown()
                except Exception:  # already stopped by the signal
                    pass
            for n in nodes:  # the loop's node first: its loop stops before a hosted
                n.safe_shutdown()  # controller's publishers go
            for n in reversed(nodes):
                n.destroy_node()
            rclpy.try_shutdown()
        finally:
            if not _OWN_PROCESS:  # in a test's process: its handler back
                signal.signal(signal.SIGINT, previous or signal.default_int_handler)
    return code
