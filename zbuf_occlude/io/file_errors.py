"""Errors about a user's file that name the file, never quote it.

numpy, trimesh, h5py and the csv module say what they could not parse by quoting it (``could
not convert string to float: '...'``, a whole ``.npy`` header over several lines, a header's
fields), and a file found in a folder may be a link to a private one (credentials, keys).  Our
errors go to the terminal, the log, the records and ``manifest.jsonl``, so an error about a
file's contents names the file, the line or the byte offset and what was expected, never the
bytes; a parser's exception is summarised by :func:`parser_failure`, never printed as is.
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Mapping

import numpy as np

__all__ = ["KEY_CHARS", "parser_failure", "dtype_text", "key_text", "value_kind", "without_quotes"]

#: Characters of a key of a user's file (a JSON object's, a column's) named in a message; a value is never quoted.
KEY_CHARS = 80

#: A quoted piece of a parser's words (``'ya29.x'``, ``"x"``), except its own tokens: a name in angle brackets
#: (``'<scalar>'``) or one punctuation mark (``Expecting ',' delimiter``).
_OWN_TOKEN = re.compile(r"""'(<[a-z ]+>|[,:{}\[\]-])'""")
#: The longest problem kept from a parser's words.
_PROBLEM_CHARS = 120


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


def without_quotes(problem: str) -> str:
    """A JSON or YAML parser's problem (``Expecting ',' delimiter``, ``could not determine a constructor for the
    tag '!secret'``) on one line, what it quotes of the file left out: ``could not determine a constructor for the
    tag``.  The parser's own tokens (``'<scalar>'``, ``','``) stay; a quote left open cuts the text there; the
    result is cut to a bounded length.
    """
    text, kept, i = " ".join(problem.split()), [], 0
    while i < len(text):
        own = _OWN_TOKEN.match(text, i)
        if own:
            kept.append(own.group(0))
            i = own.end()
        elif text[i] in "'\"":  # a quoted piece, escapes inside it skipped (repr's 'it\'s'): left out
            quote, i = text[i], i + 1
            while i < len(text) and text[i] != quote:
                i += 2 if text[i] == "\\" else 1
            if i >= len(text):
                break  # never closed: the rest is left out too
            i += 1
        else:
            kept.append(text[i])
            i += 1
    text = " ".join("".join(kept).split())
    return text if len(text) <= _PROBLEM_CHARS else text[: _PROBLEM_CHARS - 3] + "..."


def value_kind(value: object) -> str:
    """What ``value`` is, for a message, never what it holds: ``a string of 41 characters``,
    ``an object of 1 key``, ``a list of 3 items``, ``a number``, ``NaN``, ``true``, ``null``.

    A value read from a user's file may be a secret (a class map linked to a credentials file holds
    a token), so no message quotes one: it says the kind of thing found and its size.  Bounded time
    whatever the size of ``value`` (only ``len`` is taken).
    """
    if value is None:
        return "null"
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, numbers.Real):
        try:
            v = float(value)
        except OverflowError:  # an integer too large for a float (10**400)
            v = math.nan
        if math.isnan(v):
            return "NaN" if not isinstance(value, numbers.Integral) else "a whole number too large for a float"
        if math.isinf(v):
            return "an infinite number"
        return "a whole number" if isinstance(value, numbers.Integral) else "a number"
    if isinstance(value, numbers.Number):
        return "a complex number"
    if isinstance(value, str):
        return "an empty string" if not value else f"a string of {_counted(len(value), 'character')}"
    if isinstance(value, (bytes, bytearray)):
        return f"{_counted(len(value), 'byte')} of binary data"
    if isinstance(value, Mapping):
        return "an empty object" if not value else f"an object of {_counted(len(value), 'key')}"
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape}"
    if isinstance(value, (list, tuple)):
        return "an empty list" if not value else f"a list of {_counted(len(value), 'item')}"
    if isinstance(value, (set, frozenset)):
        return f"a set of {_counted(len(value), 'item')}"
    name = type(value).__name__
    return f"{'an' if name[:1].lower() in 'aeiou' else 'a'} {name}"


def _counted(n: int, noun: str) -> str:
    return f"{n:,} {noun}{'' if n == 1 else 's'}"


def key_text(key: object) -> str:
    """A key of a user's file for a message: ``'yaw_deg'`` when it is a string of at most
    :data:`KEY_CHARS` printable characters, else what it is (``a key of 5,000 characters``).

    Keys are named (they say where in the file the fault is); values never are (:func:`value_kind`).
    """
    if isinstance(key, str):
        if 0 < len(key) <= KEY_CHARS and key.isprintable():
            return repr(key)
        return f"a key of {_counted(len(key), 'character')}"
    return f"a key that is {value_kind(key)}"
