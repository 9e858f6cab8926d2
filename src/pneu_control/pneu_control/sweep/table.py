"""The sweep's tidy table: one CSV row per run, the plant sample's values beside it.

Columns: ``RUN_COLUMNS`` (sample, seed, experiment, axis, controller, gains,
e_max, rmse, unit, steady window, in_band, safety_trip, safety_errors), then one
column per sampled factor (dotted plant names in SI, discrete factors as their
label). Floats are written with ``repr`` (shortest round-trip text), so the
same runs give the same bytes, and NaN is ``nan``; a run the supervisor stopped
has e_max/rmse as the metrics computed (often ``nan``) and its trip in
``safety_trip``. The |e| envelopes of the band figures go beside it in an
``.npz`` (``envelope`` (runs, bins), ``envelope_dt_s``).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["RUN_COLUMNS", "read_table", "table_text", "write_envelopes"]

RUN_COLUMNS = (
    "sample",
    "seed",
    "experiment",
    "axis",
    "controller",
    "gains",
    "e_max",
    "rmse",
    "unit",
    "window_start_s",
    "window_end_s",
    "in_band",
    "safety_trip",
    "safety_errors",
)


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else repr(v)
    return str(v)


def table_text(
    rows: Sequence[Any], points: Sequence[dict[str, Any]], factors: Sequence[str]
) -> str:
    """CSV text of ``rows`` (:class:`~pneu_control.sweep.tasks.RunRow`, in table order),
    each with its sample's factor values from ``points``."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([*RUN_COLUMNS, *factors])
    for r in rows:
        point = points[r.sample]
        w.writerow([_cell(getattr(r, c)) for c in RUN_COLUMNS] + [_cell(point[f]) for f in factors])
    return buf.getvalue()


def _parse(column: str, text: str) -> Any:
    if column in ("sample", "seed", "safety_errors"):
        return int(text)
    if column == "in_band":
        return None if text == "" else text == "true"
    if column in ("experiment", "axis", "controller", "gains", "unit", "safety_trip"):
        return text
    try:
        return float(text)
    except ValueError:
        return text  # a discrete factor's label


def read_table(path: str | Path) -> tuple[list[str], list[dict[str, Any]]]:
    """(factor columns, rows as dicts with typed values) of a sweep CSV."""
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        header = next(reader)
        if tuple(header[: len(RUN_COLUMNS)]) != RUN_COLUMNS:
            raise ValueError(f"{path}: not a pneu sweep table (columns {header[:3]}...)")
        rows = [{c: _parse(c, v) for c, v in zip(header, line)} for line in reader]
    return header[len(RUN_COLUMNS) :], rows


def write_envelopes(path: str | Path, rows: Sequence[Any], dt_s: float) -> None:
    """The runs' |e| envelopes, padded with NaN to the longest run, in table order."""
    n = max((r.envelope.size for r in rows), default=0)
    env = np.full((len(rows), n), np.nan)
    for i, r in enumerate(rows):
        env[i, : r.envelope.size] = r.envelope
    with open(path, "wb") as fh:
        np.savez(fh, envelope=env, envelope_dt_s=np.array(dt_s))
