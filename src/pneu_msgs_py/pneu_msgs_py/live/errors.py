"""Errors of the live view (one line each, printed by the CLI without a traceback)."""

from __future__ import annotations

__all__ = ["LiveError"]


class LiveError(RuntimeError):
    """The live view cannot start: foxglove-sdk missing, port taken, bad option."""
