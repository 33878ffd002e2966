"""Numbers as fixed-point text, the bytes of ``np.savetxt(fmt="%.6f")``, made without a Python loop per row.

``np.savetxt`` formats row after row in Python (about 4 µs a row); the ModelNet text export writes
millions of rows.  Here every value of a float32 table is written by one numba loop: a float32 times
``10**decimals`` (``decimals <= 6``) is exact in float64 (24 + 20 significant bits at most), so
:func:`numpy.rint` (ties to even) rounds it as C's ``printf`` rounds the exact value (ties to even
under the default rounding mode), and the digits are cut from the rounded integer.  A table that is
not float32, holds values that are not finite, or values of 10**12 or more, is written by
``np.savetxt`` itself.
"""

from __future__ import annotations

import numba
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
    values = np.ascontiguousarray(rows).reshape(-1)
    digits = len(str(int(np.float64(np.abs(values).max())) + 1))  # a bound on the whole digits: the buffer's size
    out = np.empty(n * c * (digits + decimals + 3), dtype=np.uint8)  # sign, point, delimiter
    return out[: _write_fixed_point(values, c, decimals, ord(delimiter), out)].tobytes()


@numba.njit(cache=True, nogil=True)
def _write_fixed_point(values, columns, decimals, delimiter, out):  # pragma: no cover - numba
    """Write ``values`` (float32, row after row of ``columns``) as ``%.{decimals}f`` text into ``out``;
    return the bytes written.  Each value times ``10**decimals`` is exact in float64 and rounded
    half to even (:func:`numpy.rint`, printf's rounding of the exact value); a negative value
    that rounds to zero keeps its sign, as printf's ``-0.000000``."""
    scale = 10.0**decimals
    unit = np.int64(10) ** decimals
    reversed_digits = np.empty(24, dtype=np.uint8)
    at = 0
    for i in range(values.size):
        v = values[i]
        scaled = np.int64(abs(np.rint(np.float64(v) * scale)))
        whole, fraction = scaled // unit, scaled % unit
        if np.signbit(v):
            out[at] = 45  # "-"
            at += 1
        count = 0
        while True:
            reversed_digits[count] = 48 + whole % 10
            count += 1
            whole //= 10
            if whole == 0:
                break
        for j in range(count):
            out[at + j] = reversed_digits[count - 1 - j]
        at += count
        if decimals > 0:
            out[at] = 46  # "."
            at += 1
            for j in range(decimals - 1, -1, -1):
                out[at + j] = 48 + fraction % 10
                fraction //= 10
            at += decimals
        out[at] = delimiter if (i + 1) % columns else 10
        at += 1
    return at
