"""OFF: the one-pass parse of plain files gives what trimesh and the checks give, bit for bit, errors included."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.mesh.formats import off

_PATH = Path("mesh.off")
_NUMBERS = ["0", "-0", "1.5", "-2.25e-3", ".5", "5.", "+3", "1E5", "0.1", "123456789.123456789", "1e-400", "7e300"]


def _outcome(raw: bytes):
    """What check_off then read_off give: the arrays (with their dtypes), or the error's type and message."""
    off._plain_off.cache_clear()
    try:
        off.check_off(raw, _PATH)
        mesh = off.read_off(raw, _PATH, "off")
    except Exception as exc:  # noqa: BLE001  (every error, its type and words, is part of the result)
        return type(exc), str(exc)
    return (mesh.vertices.dtype, mesh.vertices.tobytes(), mesh.faces.dtype, mesh.faces.tobytes(), mesh.metadata,
            set(vars(mesh)), mesh.vertices.flags.writeable, mesh.faces.flags.writeable)  # fmt: skip


def _slow_outcome(raw: bytes, monkeypatch: pytest.MonkeyPatch):
    with monkeypatch.context() as patch:
        patch.setattr(off, "_plain_off", _NoPlain())
        return _outcome(raw)


class _NoPlain:
    """Stands for ``_plain_off`` when the slow path (trimesh and the checks) is the reference."""

    def __call__(self, raw: bytes) -> None:
        return None

    def cache_clear(self) -> None:
        pass


@st.composite
def _off_files(draw) -> bytes:
    """OFF text near the plain layout, with one of the departures the fast path must notice, or none."""
    n_vertices = draw(st.integers(1, 6))
    vertices = [[draw(st.sampled_from(_NUMBERS)) for _ in range(3)] for _ in range(n_vertices)]
    faces = [[3, *(draw(st.integers(0, n_vertices - 1)) for _ in range(3))] for _ in range(draw(st.integers(1, 5)))]
    lines = ["OFF", f"{n_vertices} {len(faces)} 0", *(" ".join(v) for v in vertices), *(" ".join(map(str, f)) for f in faces)]
    change = draw(st.sampled_from([
        "none", "none", "crlf", "lone_cr", "counts_on_header", "blank_lines", "tabs", "comment", "extra_vertex_token",
        "quad", "pentagon", "index_out_of_range", "cut_short", "extra_line", "short_vertex", "float_index", "letters",
        "coff", "latin1", "corners_miscounted", "no_final_newline", "leading_space", "more_counts", "negative_count", "big_index",
    ]))  # fmt: skip
    end = "\n"
    if change == "crlf":
        end = "\r\n"
    elif change == "lone_cr":
        lines[2] += "\r" + lines[2]
    elif change == "counts_on_header":
        lines[:2] = ["OFF" + lines[1]]
    elif change == "blank_lines":
        lines.insert(draw(st.integers(1, len(lines))), draw(st.sampled_from(["", "  ", "\t"])))
    elif change == "tabs":
        lines[-1] = lines[-1].replace(" ", "\t")
    elif change == "comment":
        lines.insert(1, "# made by hand")
    elif change == "extra_vertex_token":
        lines[2] += " 1"
    elif change == "quad":
        lines[-1] = f"4 0 0 0 {n_vertices - 1}"
    elif change == "pentagon":
        lines[-1] = "5 0 0 0 0 0"
    elif change == "index_out_of_range":
        lines[-1] = f"3 0 0 {n_vertices}"
    elif change == "cut_short":
        lines = lines[:-1]
    elif change == "extra_line":
        lines.append("3 0 0 0")
    elif change == "short_vertex":
        lines[2] = "1 2"
    elif change == "corners_miscounted":
        lines[-1] = draw(st.sampled_from(["4 0 0 0", "2 0 0 0"]))
    elif change == "float_index":
        lines[-1] = "3 0 0 0.0"
    elif change == "letters":
        lines[2] = "1 nan 2"
    elif change == "coff":
        lines[0] = "COFF"
    elif change == "latin1":
        lines.insert(2, "")
        return ("\n".join(lines) + "\n").encode("utf-8").replace(b"OFF\n", b"OFF \xe9\n", 1)
    elif change == "no_final_newline":
        end = ""
    elif change == "leading_space":
        lines[0] = " OFF"
    elif change == "more_counts":
        lines[1] += " 0 0"
    elif change == "negative_count":
        lines[1] = f"-{n_vertices} {len(faces)} 0"
    elif change == "big_index":
        lines[-1] = "3 0 0 99999999999999999999999"
    return ("\r\n" if end == "\r\n" else "\n").join(lines).encode() + end.encode()


@settings(max_examples=400, deadline=None)
@given(_off_files())
def test_the_one_pass_parse_gives_what_trimesh_and_the_checks_give(raw: bytes) -> None:
    with pytest.MonkeyPatch.context() as monkeypatch:
        assert _outcome(raw) == _slow_outcome(raw, monkeypatch)


def test_plain_files_take_the_one_pass_parse() -> None:
    crlf = b"OFF\r\n3 1 0\r\n0 0 0\r\n1 0 0\r\n0 1.5 -0\r\n3 0 1 2\r\n"
    for raw in (crlf, crlf.replace(b"\r\n", b"\n"), b"OFF3 1 0\n0 0 0\n1 0 0\n0 1 0\n\n3 2 1 0"):
        off._plain_off.cache_clear()
        plain = off._plain_off(raw)
        assert plain is not None
        vertices, faces = plain
        np.testing.assert_array_equal(faces, [[2, 1, 0]] if raw.startswith(b"OFF3") else [[0, 1, 2]])
        assert vertices.dtype == np.float64 and faces.dtype == np.int64 and vertices.shape == (3, 3)
    assert np.signbit(off._plain_off(crlf.replace(b"\r\n", b"\n"))[0][2, 2])  # -0 stays -0.0, as trimesh reads it


@pytest.mark.parametrize(
    "raw",
    [
        b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n# end\n",  # a comment
        b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2 2\n",  # a quad
        b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",  # an index past the vertices
        b"OFF\n3 1 0\n0 0 0\n1 0 0 9\n0 1 0\n3 0 1 2\n",  # a vertex colour
        b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1e400 0\n3 0 1 2\n",  # an infinite coordinate
        b"OFF\n3 1 0\n0 0 0\r1 0 0\n0 1 0\n3 0 1 2\n",  # a lone carriage return
    ],
)
def test_other_files_go_to_trimesh(raw: bytes) -> None:
    off._plain_off.cache_clear()
    assert off._plain_off(raw) is None


@pytest.mark.parametrize("counts", [b"99999999999999 1 0", b"1 99999999999999999 0", b"1" * 5000 + b" 1 0"])
def test_huge_declared_counts_allocate_nothing_and_keep_their_errors(counts: bytes, monkeypatch: pytest.MonkeyPatch) -> None:
    raw = b"OFF\n" + counts + b"\n0 0 0\n3 0 0 0\n"
    off._plain_off.cache_clear()
    assert off._plain_off(raw) is None
    assert _outcome(raw) == _slow_outcome(raw, monkeypatch)
