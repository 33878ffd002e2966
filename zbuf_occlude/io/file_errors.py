"""Errors about a user's file that name the file, never quote it.

numpy, trimesh, h5py and the csv module say what they could not parse by quoting it (``could
not convert string to float: '...'``, a whole ``.npy`` header over several lines, a header's
fields), and a file found in a folder may be a link to a private one (credentials, keys).  Our
errors go to the terminal, the log, the records and ``manifest.jsonl``, so an error about a
file's contents names the file, the line or the byte offset and what was expected, never the
bytes; a parser's exception is summarised by :func:`parser_failure`, never printed as is.
"""

from __future__ import annotations

__all__ = ["parser_failure", "dtype_text"]


def dtype_text(dtype: object) -> str:
    """A file's array dtype for a message: ``float32``, ``|S8``..., or ``structured records`` for one
    with named fields, whose names come from the file (and are not quoted)."""
    fields = getattr(dtype, "fields", None)
    return "structured records" if fields else str(dtype)


def parser_failure(exc: BaseException) -> str:
    """A few words on why a parser failed on a file, for a one-line message: never its text.

    Parameters
    ----------
    exc : BaseException
        What numpy, trimesh, h5py, csv... raised on the file's bytes.

    Returns
    -------
    str
        The system's reason for an ``OSError`` (``Permission denied``), the offset of the first
        byte that is not text for a ``UnicodeDecodeError``, else ``"<Type> from the parser"``:
        the exception's message may quote the file, so it is left out.
    """
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    import zipfile

    if isinstance(exc, zipfile.BadZipFile):
        return "not a zip file, or a damaged one"
    if isinstance(exc, ValueError) and "allow_pickle" in str(exc):  # numpy's refusal of an object array
        return "it holds pickled Python objects, which are never loaded"
    if isinstance(exc, UnicodeDecodeError):
        return f"byte {exc.start:,} is not {exc.encoding} text"
    return f"{type(exc).__name__} from the parser"
