"""JSON from files a user opens (data-set metadata, journals, scene and sensor files): one reader.

``json.loads`` recurses once per level of nesting, so ``[[[[...]]]]`` a few thousand levels deep
raises ``RecursionError`` (not a ``ValueError``), and a document just under the interpreter's
limit makes every later recursive walk of it fragile.  No file this project reads needs more
than a few levels, so :func:`loads_json` refuses anything deeper than :data:`MAX_JSON_DEPTH`,
naming the file, as it refuses text that is not JSON.
"""

from __future__ import annotations

import json
import os
from typing import Any

from zbuf_occlude.errors import InvalidInputError, ZbufOccludeError
from zbuf_occlude.io.caps import MAX_METADATA_BYTES
from zbuf_occlude.io.file_errors import without_quotes
from zbuf_occlude.io.regular_files import read_regular_file

__all__ = ["MAX_JSON_DEPTH", "json_depth", "loads_json", "read_json_file"]

#: Deepest nesting of arrays and objects accepted; our deepest file (a data-set card) uses 4.
MAX_JSON_DEPTH = 64


def json_depth(doc: Any, limit: int = MAX_JSON_DEPTH) -> int:
    """Nesting depth of a parsed JSON value (a scalar is 0, ``[]`` is 1), counted without recursion.

    Stops counting once ``limit`` is passed and returns ``limit + 1``.
    """
    deepest = 0
    stack: list[tuple[Any, int]] = [(doc, 0)]
    while stack:
        value, depth = stack.pop()
        if isinstance(value, dict):
            value = list(value.values())
        if not isinstance(value, list):
            continue
        depth += 1
        if depth > limit:
            return depth
        deepest = max(deepest, depth)
        stack.extend((v, depth) for v in value)
    return deepest


def loads_json(text: str | bytes, *, what: str, max_depth: int = MAX_JSON_DEPTH) -> Any:
    """Parse JSON text that came from a file a user opened.

    Parameters
    ----------
    text : str or bytes
        The file's content.
    what : str
        The file (or field) to name in the error.
    max_depth : int
        Deepest nesting of arrays and objects accepted (:data:`MAX_JSON_DEPTH`).

    Raises
    ------
    InvalidInputError
        ``text`` is not JSON, or it nests deeper than ``max_depth`` (the message names ``what``).
    """
    try:
        doc = json.loads(text)
    except RecursionError:
        doc, depth = None, None
    except json.JSONDecodeError as exc:  # its words may quote a character of the file: left out
        raise InvalidInputError(f"{what} is not valid JSON: {without_quotes(exc.msg)}: line {exc.lineno} column {exc.colno}") from None
    except UnicodeDecodeError as exc:
        raise InvalidInputError(f"{what} is not valid JSON: byte {exc.start:,} is not {exc.encoding} text") from None
    except (ValueError, TypeError) as exc:  # an integer of over 4,300 digits; bytes of no known encoding
        raise InvalidInputError(f"{what} is not valid JSON: {without_quotes(str(exc))}") from None
    else:
        depth = json_depth(doc, max_depth)
    if depth is None or depth > max_depth:
        raise InvalidInputError(f"{what} nests arrays or objects deeper than {max_depth} levels; it is not a file of ours")
    return doc


def read_json_file(
    path: str | os.PathLike,
    *,
    max_depth: int = MAX_JSON_DEPTH,
    max_bytes: int = MAX_METADATA_BYTES,
    within: str | os.PathLike | None = None,
    error: type[ZbufOccludeError] = InvalidInputError,
) -> Any:
    """:func:`loads_json` of a UTF-8 file, read as :func:`~zbuf_occlude.io.regular_files.read_regular_file` reads.

    Parameters
    ----------
    path : str or PathLike
    max_depth : int
        Deepest nesting accepted (:data:`MAX_JSON_DEPTH`).
    max_bytes : int
        The cap on the file's size, checked before a byte is read
        (:data:`~zbuf_occlude.io.caps.MAX_METADATA_BYTES`).
    within : str or PathLike, optional
        The folder ``path`` was named from: it must stay inside it, links resolved.
    error : type
        The exception raised for a file that cannot be read (default
        :class:`~zbuf_occlude.errors.InvalidInputError`).

    Raises
    ------
    InvalidInputError
        The file cannot be read or decoded, is not a regular file (a FIFO), is larger than
        ``max_bytes``, is not JSON, or nests too deep (the message names it).
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    data = read_regular_file(path, max_bytes=max_bytes, error=error, within=within)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"cannot read {path}: not UTF-8 (byte {exc.start})") from None
    return loads_json(text, what=str(path), max_depth=max_depth)
