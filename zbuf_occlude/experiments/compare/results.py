"""``results.csv``: the comparison's rows written, read back and averaged."""

from __future__ import annotations

import math
import os
from collections import defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from zbuf_occlude import io
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.tables import read_csv_rows

__all__ = ["RESULT_FIELDS", "write_csv", "read_csv", "summarise", "ok_rows"]

#: Columns of ``results.csv``, in order.
RESULT_FIELDS = (
    "mesh",
    "n_faces",
    "n_points",
    "view",
    "elevation_deg",
    "azimuth_deg",
    "method",
    "sweep",
    "param",
    "time_s",
    "peak_mib",
    "n_visible",
    "n_reference_visible",
    "accuracy",
    "false_visible_rate",
    "false_hidden_rate",
    "iou",
    "chamfer",
    "error",
)


def write_csv(rows: Sequence[dict[str, Any]], path: str | os.PathLike, *, atomic: bool = True) -> Path:
    """Write rows with the columns of :data:`RESULT_FIELDS` (atomically) and return the path;
    ``atomic=False``: straight to ``path``, a temporary the caller renames (:meth:`~zbuf_occlude.io.owned.OwnedFolder.write`)."""
    return io.write_csv(path, [{k: _fmt_csv(row.get(k, "")) for k in RESULT_FIELDS} for row in rows], RESULT_FIELDS, atomic=atomic)


def _fmt_csv(value: Any) -> Any:
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)
    return value


_NUMERIC = {
    "n_faces": int, "n_points": int, "view": int, "n_visible": int, "n_reference_visible": int,
    "elevation_deg": float, "azimuth_deg": float, "time_s": float, "peak_mib": float, "accuracy": float,
    "false_visible_rate": float, "false_hidden_rate": float, "iou": float, "chamfer": float,
}  # fmt: skip


def read_csv(path: str | os.PathLike, *, within: str | os.PathLike | None = None) -> list[dict[str, Any]]:
    """Rows of a ``results.csv`` written by :func:`write_csv`, numbers parsed back.

    Read by :func:`~zbuf_occlude.io.tables.read_csv_rows`: a regular file of at most
    :data:`~zbuf_occlude.io.caps.MAX_TABLE_BYTES`, inside ``within`` (the comparison's output
    folder) once links are resolved, when given.

    Raises
    ------
    InvalidInputError
        The file is missing, not a regular file (a FIFO), too large, not UTF-8 CSV, or holds a
        value that is not a number where one belongs; the message names it.
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    rows = []
    for raw in read_csv_rows(path, within=within):
        row: dict[str, Any] = dict(raw)
        try:
            for key, typ in _NUMERIC.items():
                if row.get(key, "") != "":
                    row[key] = typ(float(row[key])) if typ is int else typ(row[key])
            if row.get("param", "") != "":
                row["param"] = int(row["param"])
        except (TypeError, ValueError, OverflowError) as exc:  # a word, a short row, int(float('inf'))
            raise InvalidInputError(f"{path}: not a results table of ours, a value is not a number ({exc})") from None
        rows.append(row)
    return rows


def ok_rows(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows without an error that carry a time."""
    return [r for r in rows if not r.get("error") and r.get("time_s", "") != ""]


def summarise(rows: Sequence[dict[str, Any]], by: Sequence[str] = ("method", "n_points"), sweep: str = "") -> dict[tuple, dict[str, float]]:
    """Mean of every metric over the rows (without errors) sharing the ``by`` keys.

    Returns
    -------
    dict
        ``key tuple -> {"time_s", "accuracy", ..., "views"}`` (``views`` = number of rows).
    """
    groups: dict[tuple, list[dict[str, Any]]] = defaultdict(list)
    for r in ok_rows(rows):
        if r.get("sweep", "") == sweep:
            groups[tuple(r[k] for k in by)].append(r)
    out = {}
    for key, group in groups.items():
        stats = {}
        for metric in ("time_s", "accuracy", "false_visible_rate", "false_hidden_rate", "iou", "chamfer", "peak_mib"):
            values = [float(r[metric]) for r in group if r.get(metric, "") != "" and not math.isnan(float(r[metric]))]
            stats[metric] = float(np.mean(values)) if values else math.nan
        stats["views"] = len(group)
        out[key] = stats
    return out
