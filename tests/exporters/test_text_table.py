"""``fixed_point_table_bytes``: the bytes of ``np.savetxt(fmt="%.6f")``, whatever the values."""

from __future__ import annotations

import io

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from zbuf_occlude.exporters.text_table import fixed_point_table_bytes


def _savetxt(rows: np.ndarray, decimals: int, delimiter: str) -> bytes:
    buffer = io.StringIO()
    np.savetxt(buffer, rows, fmt=f"%.{decimals}f", delimiter=delimiter)
    return buffer.getvalue().encode()


float32s = st.floats(width=32, allow_nan=True, allow_infinity=True)
tables = hnp.arrays(np.float32, hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=7), elements=float32s)


@settings(max_examples=300, deadline=None)
@given(tables, st.integers(0, 7), st.sampled_from([",", " ", "\t"]))
@example(np.array([[0.0078125, -0.0078125, -0.0, -1e-9, 0.5, 2.5]], np.float32), 6, ",")  # ties go to even, as printf
@example(np.array([[1.5, 2.5, -0.5, 9.9999995, 123456.7, -0.25]], np.float32), 0, ",")
def test_the_bytes_are_savetxts(rows, decimals, delimiter):
    assert fixed_point_table_bytes(rows, decimals=decimals, delimiter=delimiter) == _savetxt(rows, decimals, delimiter)


def test_a_sample_of_unit_values_is_written_by_the_fast_path_and_reads_back():
    rows = np.random.default_rng(0).uniform(-1, 1, size=(2048, 6)).astype(np.float32)
    text = fixed_point_table_bytes(rows)
    assert text == _savetxt(rows, 6, ",")
    np.testing.assert_allclose(np.loadtxt(io.BytesIO(text), delimiter=","), rows, atol=5e-7)
