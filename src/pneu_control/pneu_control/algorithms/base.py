"""The one interface every control algorithm implements, and its per-step input.

Algorithms work in the paper's units (DESIGN §5): y in mm (linear position)
or rpm (rotary speed), the reference as (r, ṙ, r̈) in the same units, the
command as the valve-voltage deviation from the neutral 5 V (V). The
:class:`~pneu_control.controller.axis.AxisController` converts SI at its
boundary, runs the tracking differentiator when ``uses_td``, fills one
:class:`StepInput` per sample and adds the neutral voltage to the result.

Per sample the controller calls exactly one of

- ``start(inp, u_prev, hint) -> u`` -- first sample of this algorithm.
  ``u_prev`` is None on a cold start (states from the measurement,
  disturbance estimate and integral zero); on a run-time switch or parameter
  change it is the last command, ``inp.u_applied`` the one on the valve
  during the last period and ``hint = (y, ẏ, ÿ)`` the previous algorithm's
  estimates (NaN if it had none). The states are initialised *physically
  consistently* (z3 = ÿ − b0 u_applied, assuming ÿ = 0 when unknown); PID
  chooses its integral so that its output equals ``u_prev``. Whatever
  difference remains between the returned command and ``u_prev`` is blended
  out by the controller (a decaying offset, ``bumpless_time_s``), so the
  valve command never jumps.
- ``update(inp) -> u`` -- every later sample.

``KernelAlgorithm`` is the documented way to write one (DESIGN §12): its
steps are kernels on records, run here and in the compiled loop alike.
Both return the saturated deviation and leave readable attributes:
``z1, z2, z3`` (observer states, NaN if none), ``s`` (sliding variable, NaN
if none), ``u_raw`` (unsaturated deviation) and ``hint`` (its estimates
(y, ẏ, ÿ), handed to the next algorithm on a switch). The flags
``uses_td``, ``uses_theta`` and ``uses_pressures`` say which inputs the
algorithm reads; the controller fills ``theta`` and checks it only for an
algorithm that reads it.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple, Protocol

from pneu_msgs_py.params.records import Record, RecordType

__all__ = [
    "Algorithm",
    "AlgorithmKernel",
    "KernelAlgorithm",
    "MAX_HISTORY",
    "NAN",
    "NO_TABLE",
    "STEP_INPUT",
    "StepInput",
    "deviation_band",
    "samples",
]

NAN = float("nan")


def samples(t: float, T: float) -> int:
    """A duration as a whole number of samples, rounded up (an exact multiple stays)."""
    return int(math.ceil(t / T - 1e-9))


def deviation_band(params: Any) -> dict[str, float]:
    """The command's band as a deviation from neutral (V): ``lo``/``hi`` of the constants."""
    lim = params.limits
    return {"lo": lim.u_min - lim.u_neutral, "hi": lim.u_max - lim.u_neutral}


MAX_HISTORY = 6  # transport_delay_samples <= 5 (AxisControllerParams): d + 1 commands

# One sample's input to an algorithm (paper units), a kernel record (DESIGN §12),
# filled in place by the controller. ``y``, ``r``, ``r_dot``, ``r_ddot``: measurement and
# reference with its derivatives (mm or rpm; with ``rotary_model: angle`` and a TD
# algorithm, the angle θ and θ_r in rpm·s). ``u_applied``: the saturated deviation on the
# valve during the last sample period (V; the ESO predicts with it). ``history[:n_hist]``:
# the commands in V, oldest first -- the one on the valve during the last period, then
# the ``transport_delay_samples`` commands already sent but not yet applied (the
# controller's: read only). ``theta``: encoder angle in rpm·s (``uses_theta``).
# ``p_c1``, ``p_c2``: chamber pressures in Pa absolute (``uses_pressures``).
STEP_INPUT = RecordType(
    "StepInput",
    [
        ("y", "f", 0.0),
        ("r", "f", 0.0),
        ("r_dot", "f", 0.0),
        ("r_ddot", "f", 0.0),
        ("u_applied", "f", 0.0),
        ("theta", "f"),
        ("p_c1", "f"),
        ("p_c2", "f"),
        ("n_hist", "i", 1),
        ("history", ("f", MAX_HISTORY)),
    ],
)
StepInput = STEP_INPUT.cls

# the table argument of an algorithm without one (a kernel's signature is the same for all)
NO_TABLE: list[list[float]] = [[0.0]]


class AlgorithmKernel(NamedTuple):
    """An algorithm's three kernels (:func:`pneu_msgs_py.params.records.kernel` functions).

    ``start(c, s, table, inp, u_prev, h0, h1, h2) -> u``: ``u_prev`` NaN on a cold start;
    ``update(c, s, table, inp) -> u``; ``hint(c, s) -> (y, ẏ, ÿ)``. ``c``: the constants
    record, ``s``: the state record, ``table``: a float64[rows, n] table (or
    :data:`NO_TABLE`), ``inp``: a :data:`STEP_INPUT` record.
    """

    start: Any
    update: Any
    hint: Any


class Algorithm(Protocol):
    name: str
    uses_td: bool
    uses_theta: bool
    uses_pressures: bool
    z1: float
    z2: float
    z3: float
    s: float
    u_raw: float

    @property
    def hint(self) -> tuple[float, float, float]: ...

    def start(self, inp: Any, u_prev: float | None, hint: tuple[float, float, float]) -> float: ...

    def update(self, inp: Any) -> float: ...


class KernelAlgorithm:
    """An :class:`Algorithm` whose steps are kernels on records (the documented way, DESIGN §12).

    A subclass declares ``name``, the flags, ``CONSTANTS`` and ``STATE`` (
    :class:`~pneu_msgs_py.params.records.RecordType`; ``STATE`` has at least ``z1, z2,
    z3, s, u_raw``), ``KERNEL`` (an :class:`AlgorithmKernel`) and ``constants(params,
    axis)`` returning the filled constants record; optionally ``table(params, axis)`` and
    ``initial_state(c)``. The same kernels run here (Python) and inside the compiled
    loop (:mod:`pneu_control.fastloop`), which finds the algorithm by ``name`` there.
    Other attributes read through (state, then constants): ``alg.integral``, ``alg.kp``.
    """

    name: str = ""
    uses_td = False
    uses_theta = False
    uses_pressures = False
    CONSTANTS: RecordType
    STATE: RecordType
    KERNEL: AlgorithmKernel

    def __init__(self, params: Any, axis: str):
        self.c = self.constants(params, axis)
        self.st = self.initial_state(self.c)
        self.tab = self.table(params, axis)

    # -- what a subclass provides ---------------------------------------------
    def constants(self, params: Any, axis: str) -> Record:  # pragma: no cover - abstract
        raise NotImplementedError

    def initial_state(self, c: Record) -> Record:
        """The fresh state (the record's defaults: NaN floats, zero codes)."""
        return self.STATE.new()

    def table(self, params: Any, axis: str) -> Any:
        return NO_TABLE

    # -- the Algorithm interface ----------------------------------------------
    def start(self, inp: Any, u_prev: float | None, hint: tuple[float, float, float]) -> float:
        u = NAN if u_prev is None else u_prev
        return self.KERNEL.start(self.c, self.st, self.tab, inp, u, hint[0], hint[1], hint[2])

    def update(self, inp: Any) -> float:
        return self.KERNEL.update(self.c, self.st, self.tab, inp)

    @property
    def hint(self) -> tuple[float, float, float]:
        return self.KERNEL.hint(self.c, self.st)

    @property
    def z1(self) -> float:
        return self.st.z1

    @property
    def z2(self) -> float:
        return self.st.z2

    @property
    def z3(self) -> float:
        return self.st.z3

    @property
    def s(self) -> float:
        return self.st.s

    @property
    def u_raw(self) -> float:
        return self.st.u_raw

    def __getattr__(self, name: str) -> Any:  # only for names not found normally
        for rec in ("st", "c"):
            r = self.__dict__.get(rec)
            if r is not None and name in r.TYPE.names:
                return getattr(r, name)
        raise AttributeError(f"{type(self).__name__} has no attribute {name!r}")
