"""The driver's error hierarchy (one line each, meant for the user, never a traceback)."""

from __future__ import annotations

__all__ = [
    "DriverError",
    "DaqUnavailableError",
    "DaqSetupError",
    "DaqIoError",
    "LateCycleError",
]


class DriverError(RuntimeError):
    """Anything that stops the driver; ``str(err)`` is a complete sentence."""


class DaqUnavailableError(DriverError):
    """The NI-DAQmx driver is missing or the configured device is not visible."""

    def __init__(self, device: str, visible: list[str] | tuple[str, ...], why: str = ""):
        self.device = device
        self.visible = tuple(visible)
        seen = ", ".join(self.visible) if self.visible else "none"
        lead = why or f"DAQ device {device!r} not found"
        super().__init__(f"{lead}; devices visible: {seen}")


class DaqSetupError(DriverError):
    """Creating or configuring a task failed (wrong channel, unsupported timing...)."""


class DaqIoError(DriverError):
    """A read or write failed for a reason other than lateness."""


class LateCycleError(DriverError):
    """A hardware-timed read/write missed its sample clock (DAQmx -209800/-209801/-209802).

    Not fatal: the loop counts it as a late cycle and keeps going.
    """

    def __init__(self, codes: tuple[int, ...]):
        self.codes = tuple(codes)
        super().__init__("late cycle: DAQmx " + ", ".join(str(c) for c in self.codes))
