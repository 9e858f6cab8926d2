"""Errors of the bag writer and reader: one line, naming the file and the problem."""

from __future__ import annotations

from pathlib import Path

__all__ = [
    "BagError",
    "BagWriteError",
    "NotMcapError",
    "NotRos2Error",
    "TruncatedBagError",
    "TruncatedBagWarning",
    "MissingTopicError",
    "UnknownSchemaError",
    "EmptyBagError",
]


class BagError(Exception):
    """Base of every bag error; ``str(err)`` is ``"<path>: <problem>"`` on one line."""

    def __init__(self, path: str | Path, problem: str) -> None:
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


class BagWriteError(BagError):
    """The writer was misused (closed, bad metadata) or the file cannot be written."""


class NotMcapError(BagError):
    """The file does not start with the MCAP magic, or a bag directory holds no MCAP file."""


class NotRos2Error(BagError):
    """An MCAP file whose profile is not ``ros2`` (or whose channels are not CDR)."""


class TruncatedBagError(BagError):
    """The file ends early and nothing, or (strict mode) not everything, could be recovered."""


class TruncatedBagWarning(UserWarning):
    """The file ends early; the complete chunks were read."""


class MissingTopicError(BagError, KeyError):
    """A requested topic is not in the bag."""

    def __str__(self) -> str:  # KeyError would quote the message
        return f"{self.path}: {self.problem}"


class UnknownSchemaError(BagError):
    """A requested topic has a type or schema encoding the reader cannot decode."""


class EmptyBagError(BagError):
    """The bag holds no messages (on the requested topics)."""
