"""Open HDF5 files from anyone: only data stored inside the file itself, of the expected types.

An HDF5 file can name other files: a dataset's raw data may sit in any file on the machine
(*external storage*, ``create_dataset(..., external=[(path, offset, size)])``), a link may
point into another file (*external link*, absolute or ``../secret.h5``, resolved from the
file's folder) or to another path (*soft link*), and a *virtual dataset* maps other files'
datasets into it.  A reader that follows any of them returns another file's bytes as
points, and the SHA-256 of the shard does not cover them.  So every HDF5 file that comes
from a data set is checked by :func:`check_hdf5` before a byte of data is read:

* every link is a hard link (no soft or external links), found with h5py's low-level
  ``links.get_info``, which does not follow the link;
* every object is a group or a dataset (no committed datatypes);
* every dataset is stored inside the file (compact, contiguous or chunked layout; no
  external storage, no virtual layout), compressed only by the filters h5py writes:
  :data:`KNOWN_FILTERS` (gzip, lzf, shuffle, fletcher32);
* every dataset holds numbers, booleans or UTF-8/ASCII strings (no references, compound or
  opaque types), and, for the columns of a schema, the kind and the number of dimensions
  the schema says (:data:`Column`): a string or integer ``data`` where float32 is written is
  an error naming the file and the dataset;
* every dataset **stores the bytes its shape declares**: a dataset that declares
  ``(100000, 2048, 3)`` in a file of a few kB (its data never written, so a read returns the
  fill value) would make a reader plan, or allocate, what the file does not hold.  Stored
  uncompressed, a dataset must occupy at least its declared size; compressed, at least
  1/:data:`MAX_COMPRESSION_RATIO` of it (deflate cannot do better than about 1032:1).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple

from zbuf_occlude.errors import DatasetFormatError
from zbuf_occlude.io.file_errors import dtype_text, key_text
from zbuf_occlude.io.regular_files import check_within, open_regular_file

__all__ = ["Column", "KNOWN_FILTERS", "MAX_COMPRESSION_RATIO", "MAX_OBJECTS", "check_hdf5", "open_hdf5", "declared_nbytes"]

#: HDF5 filter ids h5py writes and zbuf_occlude accepts: deflate (gzip) 1, shuffle 2,
#: fletcher32 3, lzf 32000.  Any other filter is a plugin we do not vouch for.
KNOWN_FILTERS = {1: "gzip", 2: "shuffle", 3: "fletcher32", 32000: "lzf"}
#: Most bytes a compressed dataset may declare per byte it stores: deflate's limit is about
#: 1032:1 (a 258-byte match in under two bits), lzf's far lower; a larger ratio is a dataset
#: whose data was never written.
MAX_COMPRESSION_RATIO = 1100
#: Groups and datasets walked in one file before it is refused: a shard holds about ten.
MAX_OBJECTS = 10_000
#: numpy kinds of the dtype classes a data set may hold (``"T"``: an HDF5 string).
_KIND_NAMES = {"f": "float", "i": "signed integer", "u": "unsigned integer", "b": "boolean", "T": "string"}


class Column(NamedTuple):
    """What one dataset of a schema must be.

    Attributes
    ----------
    kinds : str
        Accepted kinds: ``"f"`` float, ``"i"`` signed and ``"u"`` unsigned integer,
        ``"b"`` boolean, ``"T"`` string (e.g. ``"iu"``: any integer).
    ndim : int
        Number of dimensions (``data (B, n, 3)``: 3).
    """

    kinds: str
    ndim: int


def _kind(dtype: Any) -> str | None:
    """The :data:`_KIND_NAMES` key of an h5py dtype, None for anything else (references, compound...)."""
    import h5py

    if h5py.check_string_dtype(dtype) is not None:
        return "T"
    if dtype.kind in "fiub" and dtype.fields is None and dtype.subdtype is None:
        return dtype.kind
    return None


def _check_dataset(ds: Any, path: Path, name: str, columns: Mapping[str, Column]) -> None:
    from h5py import h5d

    where = f"the HDF5 file {path}: dataset {key_text(name)}"
    if ds.is_virtual:
        raise DatasetFormatError(f"{where} is a virtual dataset (it maps other files' data); refused")
    dcpl = ds.id.get_create_plist()
    if dcpl.get_external_count() > 0:
        raise DatasetFormatError(f"{where} keeps its data in another file (external storage); refused")
    if dcpl.get_layout() not in (h5d.COMPACT, h5d.CONTIGUOUS, h5d.CHUNKED):
        raise DatasetFormatError(f"{where} has an unknown storage layout {dcpl.get_layout()}; refused")
    for i in range(dcpl.get_nfilters()):
        code = dcpl.get_filter(i)[0]
        if code not in KNOWN_FILTERS:
            raise DatasetFormatError(f"{where} uses the HDF5 filter {code}; only {', '.join(KNOWN_FILTERS.values())} are read")
    _check_stored_size(ds, where, compressed=dcpl.get_nfilters() > 0)
    kind = _kind(ds.dtype)
    if kind is None:
        raise DatasetFormatError(f"{where} holds {dtype_text(ds.dtype)} values (not numbers or strings); refused")
    column = columns.get(name.lstrip("/"))
    if column is None:
        return
    if kind not in column.kinds or ds.ndim != column.ndim:
        wanted = " or ".join(_KIND_NAMES[k] for k in column.kinds)
        raise DatasetFormatError(
            f"{where} holds {_KIND_NAMES[kind]} values of shape {ds.shape}; the schema says {wanted} with "
            f"{column.ndim} dimensions: the file is not a zbuf_occlude data set file"
        )


def _check_stored_size(ds: Any, where: str, *, compressed: bool) -> None:
    """Refuse a dataset that declares more bytes than it stores (module docstring)."""
    if ds.shape is None:  # an empty (null) dataspace holds nothing and declares nothing
        return
    declared, stored = declared_nbytes(ds), int(ds.id.get_storage_size())
    if declared > stored * (MAX_COMPRESSION_RATIO if compressed else 1):
        raise DatasetFormatError(
            f"{where} declares shape {ds.shape} ({declared:,} bytes) but stores {stored:,} bytes; its data was never "
            "written or the file is damaged: refused"
        )


def check_hdf5(f: Any, path: str | os.PathLike, columns: Mapping[str, Column] | None = None) -> None:
    """Check an open ``h5py.File`` holds only data stored inside it, of the expected types.

    Parameters
    ----------
    f : h5py.File
        Open for reading.
    path : str or PathLike
        The file, for messages.
    columns : mapping of str to Column, optional
        Datasets (names relative to the root) that, when present, must have these kinds
        and dimensions; others need only hold numbers or strings.

    Raises
    ------
    DatasetFormatError
        A soft or external link, a committed datatype, a virtual dataset, external raw
        storage, an unknown filter, a dataset of references, compound or opaque values,
        a dataset of another kind or rank than its column, a dataset that stores fewer bytes
        than its shape declares (:func:`_check_stored_size`), or more than
        :data:`MAX_OBJECTS` objects; the message names the file and the dataset.
    """
    import h5py
    from h5py import h5l

    path, columns = Path(path), dict(columns or {})
    pending, seen = [f["/"]], 0
    while pending:
        group = pending.pop()
        for name in group.keys():  # link names; nothing is followed yet
            seen += 1
            if seen > MAX_OBJECTS:
                raise DatasetFormatError(f"the HDF5 file {path} holds more than {MAX_OBJECTS} objects; refused")
            full = f"{group.name.rstrip('/')}/{name}"
            link = group.id.links.get_info(name.encode("utf-8")).type
            if link != h5l.TYPE_HARD:
                what = {h5l.TYPE_SOFT: "a soft link", h5l.TYPE_EXTERNAL: "an external link (to another file)"}
                raise DatasetFormatError(
                    f"the HDF5 file {path}: {key_text(full)} is {what.get(link, f'a link of type {link}')}; links are refused"
                )
            cls = group.get(name, getclass=True)
            if cls is h5py.Group:
                if full.count("/") > 1:  # a data set's files are flat; a deeper tree is not ours
                    raise DatasetFormatError(f"the HDF5 file {path}: nested group {key_text(full)}; refused")
                pending.append(group[name])
            elif cls is h5py.Dataset:
                _check_dataset(group[name], path, full, columns)
            else:
                raise DatasetFormatError(f"the HDF5 file {path}: {key_text(full)} is not a group or a dataset; refused")


def open_hdf5(path: str | os.PathLike, columns: Mapping[str, Column] | None = None, *, within: str | os.PathLike | None = None) -> Any:
    """``h5py.File(path, "r")`` after :func:`check_hdf5`; close it (or use ``with``).

    The file must be a regular file (a FIFO would block HDF5's open; it is refused unopened, by
    :func:`~zbuf_occlude.io.regular_files.open_regular_file`), inside ``within`` when given.

    Parameters
    ----------
    path : str or PathLike
    columns : mapping of str to Column, optional
        As :func:`check_hdf5`.
    within : str or PathLike, optional
        The folder ``path`` was named from: it must stay inside it, links resolved.

    Raises
    ------
    DatasetFormatError
        Not a regular file, not a readable HDF5 file, or :func:`check_hdf5` refuses it (the
        file is closed).
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    import h5py

    target = Path(path) if within is None else check_within(path, within)
    fh, _ = open_regular_file(target, error=DatasetFormatError)
    fh.close()
    try:
        f = h5py.File(target, "r")
    except OSError as exc:  # h5py says "file signature not found" for a file that is not HDF5
        raise DatasetFormatError(f"{path} is not a readable HDF5 file ({exc})") from None
    try:
        check_hdf5(f, path, columns)
    except BaseException:
        f.close()
        raise
    return f


def declared_nbytes(ds: Any) -> int:
    """Bytes a dataset holds once read whole, from its declared shape (nothing is read)."""
    n = int(ds.dtype.itemsize)
    for s in ds.shape or ():
        n *= int(s)
    return n
