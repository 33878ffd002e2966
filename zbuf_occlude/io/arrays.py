""".npy and .npz files from anyone: shapes, dtypes and sizes read from their headers, before inflating.

A ``.npz`` is a zip of ``.npy`` members, and both say what reading them will cost before a
byte of array is read: the zip directory gives each member's uncompressed size, and each
member's ``.npy`` header its shape and dtype.  A small file may declare gigabytes (a member of
zeros inflates 1000:1, a header may declare ``(10**9, 3)`` over a few bytes), so every reader of
such a file from outside asks here first: :func:`check_array_sizes` refuses a file that would
inflate past a cap, :func:`npz_member_header` gives one member's declared shape and dtype.
Only headers are read (numpy's own parser, :mod:`numpy.lib.format`); nothing is unpickled.

numpy allocates the whole array a header declares before it reads a byte of it, so the sizes
the zip directory declares must also be sizes the file can hold: members stored or deflated
(what ``numpy.savez`` and ``savez_compressed`` write), their compressed bytes inside the file, a
stored member inflating to its compressed size and a deflated one to at most
:data:`~zbuf_occlude.io.hdf5.MAX_COMPRESSION_RATIO` times it.  Otherwise a few hundred bytes
that declare gigabytes would make numpy reserve them (a ``MemoryError`` under an address-space
limit, ``ulimit -v``) before the read found the lie.

:func:`load_npy` and :func:`load_npz` are the one way to load such a file: a regular file
(inside the folder it was named from, links resolved:
:func:`~zbuf_occlude.io.regular_files.open_regular_file`), its sizes checked from the headers
as :func:`check_array_sizes` checks them, then its arrays read from that same open file with
``allow_pickle=False``; every error names the file in one line.
"""

from __future__ import annotations

import contextlib
import zipfile
import zlib
from collections.abc import Callable, Iterable, Iterator
from os import PathLike
from pathlib import Path
from typing import BinaryIO

import numpy as np
from numpy.lib import format as npy_format

from zbuf_occlude.errors import InvalidInputError, ZbufOccludeError
from zbuf_occlude.io.file_errors import parser_failure
from zbuf_occlude.io.hdf5 import MAX_COMPRESSION_RATIO
from zbuf_occlude.io.regular_files import open_regular_file

__all__ = [
    "check_array_sizes", "check_npy_sizes", "load_npy", "load_npz", "npy_header", "npz_member_header", "zip_inflated_bytes",
    "DAMAGED_NPZ_ERRORS",
]  # fmt: skip

#: What numpy and zipfile raise on a damaged ``.npy``/``.npz``: besides ``OSError``,
#: ``ValueError``, ``EOFError`` and ``BadZipFile``, ``zlib.error`` (damaged deflate data),
#: ``NotImplementedError`` (a compression method zipfile lacks) and ``RuntimeError`` (a member
#: flagged encrypted).
DAMAGED_NPZ_ERRORS = (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, NotImplementedError, RuntimeError)
#: How the members of a zip (a ``.npz``, a checkpoint) may be compressed, with the most bytes each
#: may inflate to per byte stored: numpy's ``savez`` and ``torch.save`` store them (1:1),
#: ``savez_compressed`` deflates them (deflate's limit is about 1032:1).  bzip2 and LZMA, which
#: neither writes, have no such bound.
_INFLATE_RATIO = {zipfile.ZIP_STORED: 1, zipfile.ZIP_DEFLATED: MAX_COMPRESSION_RATIO}

#: ``.npy`` format versions numpy reads: 1.0 (2-byte header length), 2.0 and 3.0 (4-byte
#: header length; 3.0 only allows UTF-8 field names, its header reads as 2.0's).
_HEADER_READERS = {
    (1, 0): npy_format.read_array_header_1_0,
    (2, 0): npy_format.read_array_header_2_0,
    (3, 0): npy_format.read_array_header_2_0,
}


def npy_header(fh: BinaryIO) -> tuple[tuple[int, ...], np.dtype]:
    """The shape and dtype the ``.npy`` header at ``fh`` declares; reads the header only.

    Parameters
    ----------
    fh : binary file
        Positioned at the start of a ``.npy`` file or ``.npz`` member.

    Returns
    -------
    shape : tuple of int
    dtype : numpy.dtype

    Raises
    ------
    ValueError
        Not a ``.npy`` header, a format version numpy does not write, or a malformed header
        (numpy's messages).
    EOFError
        The header is cut short.
    """
    version = npy_format.read_magic(fh)
    if version not in _HEADER_READERS:
        raise ValueError(f".npy format version {version[0]}.{version[1]}, not one numpy reads")
    shape, _, dtype = _HEADER_READERS[version](fh)
    return tuple(int(s) for s in shape), dtype


def npz_member_header(zf: zipfile.ZipFile, key: str) -> tuple[tuple[int, ...], np.dtype]:
    """The shape and dtype array ``key`` of an open ``.npz`` declares, before it is inflated.

    Parameters
    ----------
    zf : zipfile.ZipFile
        The ``.npz`` (``numpy.load(path).zip`` for an open :class:`numpy.lib.npyio.NpzFile`).
    key : str
        The array's name (its member is ``key + ".npy"``).

    Returns
    -------
    shape : tuple of int
    dtype : numpy.dtype

    Raises
    ------
    KeyError
        No member ``key.npy``.
    ValueError, EOFError, zipfile.BadZipFile
        The member's header is not a ``.npy`` header numpy reads, or the zip is damaged.
    """
    with zf.open(f"{key}.npy") as member:
        return npy_header(member)


def _declared_bytes(fh: BinaryIO) -> int:
    return _nbytes(*npy_header(fh))


def _nbytes(shape: tuple[int, ...], dtype: np.dtype) -> int:
    return int(np.prod(shape, dtype=object)) * dtype.itemsize


def check_array_sizes(path: str | PathLike[str], *, max_bytes: int, error: type[ZbufOccludeError] = InvalidInputError) -> None:
    """Refuse a ``.npy``/``.npz`` whose arrays would inflate past ``max_bytes``, reading only headers.

    For ``.npz``, the zip directory's uncompressed sizes (what inflating costs) and each
    member's ``.npy`` header (what numpy allocates) are both checked; a header declaring more
    than its member holds is refused too.

    Parameters
    ----------
    path : path
        A ``.npy`` (by its suffix) or a ``.npz`` (anything else).
    max_bytes : int
        The cap on the bytes the arrays inflate to.
    error : type
        The exception raised (:class:`~zbuf_occlude.errors.MeshLoadError` for files a mesh
        names, :class:`~zbuf_occlude.errors.InvalidInputError` for scans and clouds).

    Raises
    ------
    ``error``
        Naming the file (and member), the declared bytes and the cap; that it is not a regular
        file (a FIFO or a device is refused before it is read:
        :func:`zbuf_occlude.io.regular_files.open_regular_file`); or that its headers cannot be
        read (not a zip, damaged, not ``.npy``).
    """
    path = Path(path)
    fh, size = open_regular_file(path, error=error)  # zipfile and numpy would block on a FIFO
    with fh:
        _check_sizes(path, fh, size, max_bytes, error, npy=path.suffix.lower() == ".npy")


def check_npy_sizes(
    fh: BinaryIO, path: str | PathLike[str], size: int, *, max_bytes: int, error: type[ZbufOccludeError] = InvalidInputError
) -> None:
    """:func:`check_array_sizes` on the ``.npy`` already open at ``fh`` (at its start; rewound after),
    of ``size`` bytes (``os.fstat``): the file checked is the file then read, not one opened again by name."""
    _check_sizes(Path(path), fh, size, max_bytes, error, npy=True)


def load_npy(
    path: str | PathLike[str],
    *,
    max_bytes: int,
    error: type[ZbufOccludeError] = InvalidInputError,
    within: str | PathLike[str] | None = None,
) -> np.ndarray:
    """The array of a ``.npy`` file from anyone, its header checked before its body is read.

    Parameters
    ----------
    path : str or PathLike
    max_bytes : int
        The cap on the bytes the header may declare (it may not declare more than the file holds
        either), checked before the array is allocated.
    error : type
        The exception raised (:class:`~zbuf_occlude.errors.InvalidInputError` or a subclass).
    within : str or PathLike, optional
        The folder ``path`` was named from: it must stay inside it, links resolved.

    Returns
    -------
    numpy.ndarray
        The shape and dtype its header declares; never an object array (nothing is unpickled).

    Raises
    ------
    ``error``
        Naming the file: missing, not a regular file (a FIFO), a header that cannot be read or
        that declares more than the file or ``max_bytes``, a body cut short, or an object array.
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    path = Path(path)
    fh, size = open_regular_file(path, error=error, within=within)
    with fh:
        _check_sizes(path, fh, size, max_bytes, error, npy=True)
        try:
            return npy_format.read_array(fh, allow_pickle=False)
        except DAMAGED_NPZ_ERRORS as exc:
            raise error(f"{path}: cannot read its array ({parser_failure(exc)})") from None


def load_npz(
    path: str | PathLike[str],
    *,
    max_bytes: int,
    error: type[ZbufOccludeError] = InvalidInputError,
    within: str | PathLike[str] | None = None,
    keys: Iterable[str] | None = None,
    check: Callable[[dict[str, tuple[tuple[int, ...], np.dtype]]], None] | None = None,
) -> dict[str, np.ndarray]:
    """The arrays of a ``.npz`` file from anyone, its sizes checked from the headers before a member is inflated.

    Parameters
    ----------
    path : str or PathLike
    max_bytes : int
        The cap on the bytes all its members inflate to (:func:`check_array_sizes`).
    error : type
        The exception raised (:class:`~zbuf_occlude.errors.InvalidInputError` or a subclass).
    within : str or PathLike, optional
        The folder ``path`` was named from: it must stay inside it, links resolved.
    keys : iterable of str, optional
        The arrays to read (those of them the file holds); default: every ``.npy`` member.
    check : callable, optional
        Called with ``{name: (shape, dtype)}``, what each array to be read declares, before any
        is inflated; it raises to refuse the file (a shape or dtype that is not the caller's).

    Returns
    -------
    dict of str to numpy.ndarray
        Array name (its member's name without ``.npy``) to array, in the zip's order; never an
        object array (nothing is unpickled).

    Raises
    ------
    ``error``
        Naming the file: missing, not a regular file (a FIFO), not a zip, members inflating past
        ``max_bytes`` or declaring more than they hold, damaged data, or an object array.
    ZbufOccludeError
        What ``check`` raises.
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    path = Path(path)
    wanted = None if keys is None else set(keys)
    fh, size = open_regular_file(path, error=error, within=within)
    with fh, _headers_read(path, error), zipfile.ZipFile(fh) as zf:
        headers = _npz_headers(path, zf, size, max_bytes, error)  # every member's, read once
        names = [n.removesuffix(".npy") for n in headers if n.endswith(".npy")]
        names = [key for key in names if wanted is None or key in wanted]
        if check is not None:
            check({key: headers[f"{key}.npy"] for key in names})
        try:
            arrays = {}
            for key in names:
                with zf.open(f"{key}.npy") as member:
                    arrays[key] = npy_format.read_array(member, allow_pickle=False)
            return arrays
        except DAMAGED_NPZ_ERRORS as exc:
            raise error(f"{path}: cannot read its arrays ({parser_failure(exc)})") from None


def zip_inflated_bytes(
    path: str | PathLike[str], zf: zipfile.ZipFile, size: int, *, error: type[ZbufOccludeError] = InvalidInputError, writer: str = "numpy"
) -> int:
    """Bytes the members of the open zip ``zf`` inflate to, once checked to be bytes the file can hold.

    A reader allocates each member's declared (inflated) size before it reads a byte of it
    (numpy, torch's zip reader), so the directory's sizes are checked first: every member stored
    or deflated, a stored one inflating to its compressed size, a deflated one to at most
    :data:`~zbuf_occlude.io.hdf5.MAX_COMPRESSION_RATIO` times it, and all the compressed bytes
    inside the file's ``size``.  Only the zip directory is read.

    Parameters
    ----------
    path : str or PathLike
        The file, for the messages.
    zf : zipfile.ZipFile
        The file, open.
    size : int
        Its bytes (``os.fstat``).
    error : type
        The exception raised.
    writer : str
        What writes such files stored or deflated, named in the message for another method.

    Returns
    -------
    int
        The sum of the members' declared inflated sizes.

    Raises
    ------
    ``error``
        Naming the file (and the member): a member compressed another way, declaring more than
        its compression can hold, or compressed bytes past the end of the file.
    """
    members = zf.infolist()
    # members are named by their place in the zip directory: their names come from the file
    for number, m in enumerate(members, 1):
        ratio = _INFLATE_RATIO.get(m.compress_type)
        if ratio is None:
            raise error(f"{path}: member {number} is compressed with zip method {m.compress_type}; only stored or deflated "
                        f"members ({writer}) are read")  # fmt: skip
        if m.file_size > m.compress_size * ratio or (ratio == 1 and m.file_size != m.compress_size):
            raise error(f"{path}: member {number} declares {m.file_size:,} bytes inflated from {m.compress_size:,}, "
                        "more than its compression can hold; the file is damaged or forged")  # fmt: skip
    stored = sum(m.compress_size for m in members)
    if stored > size:
        raise error(f"{path}: its members declare {stored:,} bytes of data in a file of {size:,}; the file is damaged or forged")
    return sum(m.file_size for m in members)


@contextlib.contextmanager
def _headers_read(path: Path, error: type[ZbufOccludeError]) -> Iterator[None]:
    """Turn what numpy and zipfile raise on damaged headers into ``error`` naming ``path``."""
    try:
        yield
    except ZbufOccludeError:
        raise
    except DAMAGED_NPZ_ERRORS as exc:
        raise error(f"{path}: cannot read its array headers ({parser_failure(exc)})") from None


def _check_sizes(path: Path, fh: BinaryIO, size: int, max_bytes: int, error: type[ZbufOccludeError], *, npy: bool) -> None:
    """:func:`check_array_sizes` on the open file ``fh`` (rewound after)."""
    with _headers_read(path, error):
        if npy:
            declared = _declared_bytes(fh)
            if declared > min(max_bytes, size):
                raise error(f"{path}: its header declares {declared:,} bytes of array, more than the file "
                            f"({size:,} bytes) or the {max_bytes:,} accepted")  # fmt: skip
        else:
            with zipfile.ZipFile(fh) as zf:
                _npz_headers(path, zf, size, max_bytes, error)
    fh.seek(0)


def _npz_headers(
    path: Path, zf: zipfile.ZipFile, size: int, max_bytes: int, error: type[ZbufOccludeError]
) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Every member's declared ``(shape, dtype)``, by member name, once the sizes are checked
    (``size``: the bytes of the ``.npz``; module docstring)."""
    members = zf.infolist()
    inflated = zip_inflated_bytes(path, zf, size, error=error, writer="numpy.savez, numpy.savez_compressed")
    if inflated > max_bytes:
        raise error(f"{path}: its members inflate to {inflated:,} bytes, more than the {max_bytes:,} accepted")
    headers = {}
    for number, m in enumerate(members, 1):
        with zf.open(m) as member:
            shape, dtype = headers[m.filename] = npy_header(member)
        declared = _nbytes(shape, dtype)
        if declared > m.file_size:
            raise error(f"{path}: member {number} declares {declared:,} bytes of array but holds {m.file_size:,}")
    return headers
