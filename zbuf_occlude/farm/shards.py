"""Which objects one task of a sharded farm run renders (``--shard I/N``)."""

from __future__ import annotations

import re
from collections.abc import Sequence

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.inputs.plan import FarmObject

__all__ = ["parse_shard", "select_shard"]


def parse_shard(text: str) -> tuple[int, int]:
    """``"I/N"`` → ``(I, N)`` with ``0 <= I < N``.

    Raises
    ------
    InvalidInputError
        Malformed or out of range.
    """
    m = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", text)
    if not m or not 0 <= int(m.group(1)) < int(m.group(2)):
        raise InvalidInputError(f"--shard must be I/N with 0 <= I < N (e.g. 3/16 for ${{SLURM_ARRAY_TASK_ID}}/16), got {text!r}")
    return int(m.group(1)), int(m.group(2))


def select_shard(objects: Sequence[FarmObject], index: int, count: int) -> list[FarmObject]:
    """The ``index``-th of ``count`` deterministic partitions (object ``i`` goes to task ``i mod count``;
    round robin spreads classes and mesh sizes evenly)."""
    if not 0 <= index < count:
        raise InvalidInputError(f"shard index must satisfy 0 <= I < N, got {index}/{count}")
    return [o for o in objects if o.index % count == index]
