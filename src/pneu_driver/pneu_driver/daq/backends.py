"""Backends by name: ``nidaqmx`` (the rig) or one registered by another package (``sim``).

``backend`` is one ``KIND[:key=value,...]`` string (the project's one parser,
:func:`pneu_msgs_py.params.spec.parse_spec`): the driver node's ``backend``
parameter, ``rig.launch.py backend:=...`` and ``pneu rig --backend ...``.

- ``nidaqmx`` -- :class:`~pneu_driver.daq.nidaqmx_backend.NidaqmxBackend`, no options;
- any name a package registers in the ``pneu_driver.backends`` entry-point
  group, as ``name = module:factory`` with ``factory(rig, **options) ->
  DaqBackend``. pneu_sim registers ``sim`` (the twin as a simulated
  PCI-6221, :mod:`pneu_sim.daq_sim.backend`): pneu_driver finds it without
  importing pneu_sim (DESIGN §2: pneu_sim depends on pneu_driver, not back).
  A factory may carry ``factory.check_options(**options)``: :func:`check_backend`
  then refuses a bad option before anything is opened, printed or written.
"""

from __future__ import annotations

from importlib.metadata import entry_points
from typing import Any

from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.spec import parse_spec

from pneu_driver.daq.backend import DaqBackend
from pneu_driver.daq.rig import RigParams

__all__ = ["ENTRY_POINT_GROUP", "backend_kind", "backend_names", "check_backend", "make_backend"]

ENTRY_POINT_GROUP = "pneu_driver.backends"


def _registered() -> dict[str, Any]:
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def backend_names() -> list[str]:
    """``nidaqmx`` and every registered backend name."""
    return ["nidaqmx", *sorted(n for n in _registered() if n != "nidaqmx")]


def backend_kind(spec: str) -> str:
    """The KIND of a backend spec (``sim:seed=1`` -> ``sim``)."""
    return parse_spec(spec, "backend")[0]


def _factory(kind: str) -> Any:
    found = _registered().get(kind)
    if found is None:
        raise ParamError(
            "backend", kind, "one of " + ", ".join(backend_names()) + " (sim: install pneu_sim)"
        )
    return found.load()


def check_backend(spec: str) -> str:
    """The KIND of ``spec``, its options checked without opening anything (one ParamError)."""
    kind, options = parse_spec(spec, "backend")
    if kind == "nidaqmx":
        if options:
            raise ParamError(f"backend {kind}", ",".join(options), "no options")
        return kind
    check = getattr(_factory(kind), "check_options", None)
    if check is not None:
        check(**options)
    return kind


def make_backend(spec: str, rig: RigParams) -> DaqBackend:
    """The backend ``spec`` names, built for ``rig``; a bad name or option is one ParamError line."""
    kind, options = parse_spec(spec, "backend")
    if kind == "nidaqmx":
        if options:
            raise ParamError(f"backend {kind}", ",".join(options), "no options")
        from pneu_driver.daq.nidaqmx_backend import NidaqmxBackend

        return NidaqmxBackend(rig)
    return _factory(kind)(rig, **options)
