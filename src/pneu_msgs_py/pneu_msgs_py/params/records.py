"""Kernel records: the one way a controller's or a safety rule's step is written (DESIGN §12).

A control step (an algorithm's ``start``/``update``, a reference, the TD, the axis
logic, a supervisor rule) is written **once**, as a plain function on *records*:
objects with named fields (``p.kp``, ``s.z1``), decorated with :func:`kernel`.

- Called from Python (the in-process runner, the ROS nodes, the driver loop), the
  function runs as the Python it is, on a :class:`Record` instance: a ``__slots__``
  object holding Python floats and ints, as fast as the attributes of a hand-written
  class.
- Called from a numba-compiled function (the compiled closed loop,
  :mod:`pneu_control.fastloop`), the same function is compiled into it
  (:func:`numba.extending.register_jitable`), on numba records: elements of numpy
  structured arrays with the same fields (:meth:`RecordType.array`).

So there is no second copy to keep in step: the compiled loop and the Python cores
run the same source, and the tests compare CPython's floating point with the
compiled one (no fastmath, the same libm calls: bit-identical when the source
avoids the two constructs LLVM rewrites -- a constant ``x ** 2`` becomes ``x * x``,
so a squared term reads its exponent from a field).

Field kinds: ``"f"`` float64 (default NaN), ``"i"`` int64 (default 0; booleans and
option codes), ``("f", n)`` / ``("i", n)`` a fixed-length float64 / int64 array (default
zeros; a Python list in the Python record); a third element sets the Python record's default.

Without numba (a rig PC may run the driver without it) :func:`kernel` leaves the
function as it is: everything runs in Python.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

try:  # the compiled loop needs numba; the Python cores do not
    from numba.extending import register_jitable as _register_jitable
except ImportError:  # pragma: no cover - numba is a dependency of the twin and the control
    _register_jitable = None

__all__ = ["JIT", "Record", "RecordType", "kernel"]

# how every kernel is compiled into its caller: no fastmath (no FMA contraction, no
# reassociation), numpy's error model (x / 0 is inf, as the loop expects; Python's
# ZeroDivisionError is avoided by the kernels' own guards), no reference counting
# (nothing inside allocates an array; the caller allocates)
JIT = {"error_model": "numpy", "_nrt": False}

FieldSpec = tuple  # (name, "f" | "i" | ("f", n) | ("i", n)[, default])


def kernel(fn: Callable) -> Callable:
    """Mark ``fn`` as a kernel: plain Python when called from Python, compiled into numba callers."""
    if _register_jitable is None:
        return fn
    return _register_jitable(**JIT)(fn)


class Record:
    """A record of named fields (a :class:`RecordType`'s Python side). Fields set by keyword."""

    __slots__ = ()
    TYPE: RecordType  # set by RecordType

    def __init__(self, **values: Any):
        for name, kind, default in self.TYPE.defaults:
            setattr(self, name, list(default) if isinstance(kind, tuple) else default)
        for name, v in values.items():
            setattr(self, name, v)  # an unknown name raises AttributeError (__slots__)

    def values(self) -> dict[str, Any]:
        """Every field's value (arrays as lists), in declaration order."""
        return {name: getattr(self, name) for name, _ in self.TYPE.fields}

    def store(self, out: Any) -> None:
        """Copy every field into ``out``, an element of :meth:`RecordType.array` (by name)."""
        for name, kind in self.TYPE.fields:
            v = getattr(self, name)
            if isinstance(kind, tuple):
                out[name][: len(v)] = v
            else:
                out[name] = v

    def load(self, src: Any) -> None:
        """Copy every field from ``src`` (a numpy record of the same type) into this one."""
        for name, kind in self.TYPE.fields:
            v = src[name]
            if isinstance(kind, tuple):
                setattr(self, name, [float(x) if kind[0] == "f" else int(x) for x in v])
            elif kind == "f":
                setattr(self, name, float(v))
            else:
                setattr(self, name, int(v))

    def copy(self) -> Record:
        out = type(self)()
        for name, kind in self.TYPE.fields:
            v = getattr(self, name)
            setattr(out, name, list(v) if isinstance(kind, tuple) else v)
        return out

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}={v!r}" for k, v in self.values().items())
        return f"{type(self).__name__}({inner})"


class RecordType:
    """One list of named fields, two forms: a Python :class:`Record` class and a numpy dtype.

    ``RecordType("PidParams", [("kp", "f"), ("aw", "i"), ...])``; ``.new(**values)`` a
    Python record; ``.array(n)`` n numpy records (zeros) for the compiled loop.
    """

    def __init__(self, name: str, fields: Iterable[FieldSpec]):
        self.name = name
        specs = tuple(fields)
        self.fields: tuple[tuple[str, Any], ...] = tuple((f[0], f[1]) for f in specs)
        self.defaults = tuple((f[0], f[1], f[2] if len(f) > 2 else _default(f[1])) for f in specs)
        names = [f for f, _ in self.fields]
        if len(set(names)) != len(names):
            raise ValueError(f"record {name}: a field is declared twice in {names}")
        self.dtype = np.dtype([(f, _np_kind(k)) for f, k in self.fields])
        self.cls: type[Record] = type(name, (Record,), {"__slots__": tuple(names)})
        self.cls.TYPE = self

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(f for f, _ in self.fields)

    def new(self, **values: Any) -> Record:
        return self.cls(**values)

    def array(self, n: int) -> np.ndarray:
        """``n`` records for the compiled loop, zero-filled (a structured array)."""
        return np.zeros(n, dtype=self.dtype)


def _default(kind: Any) -> Any:
    if isinstance(kind, tuple):
        return [0.0 if kind[0] == "f" else 0] * kind[1]
    return math.nan if kind == "f" else 0


def _np_kind(kind: Any) -> Any:
    if isinstance(kind, tuple):
        if kind[0] not in ("f", "i") or not (isinstance(kind[1], int) and kind[1] > 0):
            raise ValueError(f"array field kind {kind!r}; allowed: ('f', n > 0), ('i', n > 0)")
        return (np.float64 if kind[0] == "f" else np.int64, (kind[1],))
    if kind == "f":
        return np.float64
    if kind == "i":
        return np.int64
    raise ValueError(f"field kind {kind!r}; allowed: 'f', 'i', ('f', n), ('i', n)")
