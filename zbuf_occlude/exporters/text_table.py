"""Numbers as fixed-point text, the bytes of ``np.savetxt(fmt="%.6f")``, made without a Python loop per row.

``np.savetxt`` formats row after row in Python (about 4 µs a row); the ModelNet text export writes
millions of rows.  Here every value of a float32 table is written at once: a float32 times
``10**decimals`` (``decimals <= 6``) is exact in float64 (24 + 20 significant bits at most), so
:func:`numpy.rint` (ties to even) rounds it as C's ``printf`` rounds the exact value (ties to even
under the default rounding mode), and the digits are cut from the rounded integer.  A table that is
not float32, holds values that are not finite, or values of 10**12 or more, is written by
``np.savetxt`` itself.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.io.encodings import text_table_bytes

__all__ = ["fixed_point_table_bytes"]

#: Most decimals for which a float32 times 10**decimals is exact in float64 (and so rounds as printf).
MAX_DECIMALS = 6
#: Magnitudes from which the table is left to ``np.savetxt`` (the int64 digits stay exact below it).
MAX_MAGNITUDE = 1e12


def fixed_point_table_bytes(rows: NDArray[np.floating], *, decimals: int = 6, delimiter: str = ",") -> bytes:
    """``rows (N, C)`` as text, one row a line, each value ``%.{decimals}f``: the bytes of ``np.savetxt``.

    Parameters
    ----------
    rows : (N, C) float32
        The table (another dtype is written by ``np.savetxt``).
    decimals : int
        Digits after the point, 0 to :data:`MAX_DECIMALS` (more: ``np.savetxt``).
    delimiter : str
        One ASCII character between the values of a row.

    Returns
    -------
    bytes
        ASCII, ``\\n`` after each row; ``-0.000000`` for a negative value that rounds to zero, as printf.
    """
    rows = np.asarray(rows)
    simple = rows.ndim == 2 and rows.dtype == np.float32 and 0 <= decimals <= MAX_DECIMALS and len(delimiter.encode()) == 1
    if not simple or not rows.size or not np.all(np.abs(rows) < MAX_MAGNITUDE):  # NaN fails the test too
        return text_table_bytes(rows, fmt=f"%.{decimals}f", delimiter=delimiter)
    n, c = rows.shape
    values = rows.reshape(-1)
    scaled = np.abs(np.rint(values.astype(np.float64) * 10.0**decimals)).astype(np.int64)
    whole, fraction = np.divmod(scaled, 10**decimals)
    digits = len(str(int(whole.max())))
    point = int(decimals > 0)
    width = 1 + digits + point + decimals + 1  # sign, whole digits, point, decimals, delimiter; 0 bytes pad
    out = np.zeros((n * c, width), dtype=np.uint8)
    for j in range(decimals):
        out[:, width - 2 - j] = 48 + (fraction // 10**j) % 10
    if point:
        out[:, width - 2 - decimals] = ord(".")
    last_whole = width - 2 - decimals - point
    n_digits = np.ones(n * c, dtype=np.int64)
    for j in range(digits):
        has = whole >= 10**j if j else np.ones(n * c, dtype=bool)
        n_digits += has if j else 0
        out[has, last_whole - j] = 48 + (whole[has] // 10**j) % 10
    negative = np.flatnonzero(np.signbit(values))
    out[negative, last_whole - n_digits[negative]] = ord("-")
    out[:, width - 1] = ord(delimiter)
    out[c - 1 :: c, width - 1] = ord("\n")
    flat = out.reshape(-1)
    return flat[flat != 0].tobytes()
