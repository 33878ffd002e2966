"""Arrays and figures encoded in memory, for the layer's writers to write (never to a path here).

A writer outside :mod:`zbuf_occlude.io` never opens a path: it encodes what it has into bytes
here and hands them to :meth:`zbuf_occlude.io.owned.OwnedFolder.write_bytes` or
:func:`zbuf_occlude.io.atomic.write_bytes`, which hold the lock, the ledger and the atomic
rename.  numpy's own writers make the ``.npy``/``.npz`` bytes (:mod:`numpy.lib.format`), and
matplotlib's ``savefig`` the PNG.
"""

from __future__ import annotations

import io
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["npy_bytes", "npz_bytes", "png_bytes", "text_table_bytes"]


def npy_bytes(array: ArrayLike) -> bytes:
    """``array`` as the bytes of a ``.npy`` file (``allow_pickle=False``: object arrays are refused).

    Raises
    ------
    ValueError
        ``array`` holds Python objects (it would need pickling).
    """
    buffer = io.BytesIO()
    np.save(buffer, np.asarray(array), allow_pickle=False)
    return buffer.getvalue()


def npz_bytes(arrays: Mapping[str, ArrayLike], *, compressed: bool = False) -> bytes:
    """``arrays`` as the bytes of a ``.npz`` file, one member per key (``np.savez`` or, with
    ``compressed``, ``np.savez_compressed``)."""
    buffer = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(buffer, **{k: np.asarray(v) for k, v in arrays.items()})
    return buffer.getvalue()


def text_table_bytes(rows: ArrayLike, *, fmt: str = "%.6f", delimiter: str = ",") -> bytes:
    """``rows (N, C)`` as text, one row per line (``np.savetxt``'s format), encoded as UTF-8."""
    buffer = io.StringIO()
    np.savetxt(buffer, np.asarray(rows), fmt=fmt, delimiter=delimiter)
    return buffer.getvalue().encode("utf-8")


def png_bytes(figure: Any, *, dpi: int = 120) -> bytes:
    """A matplotlib ``figure`` as the bytes of a PNG (``figure.savefig(..., format="png")``)."""
    buffer = io.BytesIO()
    figure.savefig(buffer, dpi=dpi, format="png")
    return buffer.getvalue()
