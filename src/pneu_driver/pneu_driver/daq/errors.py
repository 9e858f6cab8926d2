"""The driver's error hierarchy (one line each, meant for the user, never a traceback)."""

from __future__ import annotations

__all__ = [
    "DriverError",
    "DaqUnavailableError",
    "DaqSetupError",
    "DaqIoError",
    "LateCycleError",
    "MIN_MISSED",
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


# the fewest sample clocks each DAQmx late code says were missed (-209801, a late write, says
# nothing about the read side)
MIN_MISSED = {-209800: 1, -209802: 1, -209803: 3, -201027: 3}


class LateCycleError(DriverError):
    """A hardware-timed read/write missed its sample clock (DAQmx -209800/-209801/-209802/
    -209803/-201027, see ``nidaqmx_backend.LATE_CODES``).

    Not fatal: the loop counts it as a late cycle and keeps going.
    """

    def __init__(self, codes: tuple[int, ...]):
        self.codes = tuple(codes)
        super().__init__("late cycle: DAQmx " + ", ".join(str(c) for c in self.codes))

    @property
    def min_missed(self) -> int:
        """Sample clocks known to be missed (DAQmx does not say how many beyond 1 or 3)."""
        return max((MIN_MISSED.get(c, 0) for c in self.codes), default=0)
