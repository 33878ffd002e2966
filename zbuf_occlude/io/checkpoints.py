"""PyTorch checkpoints: encoded in memory for the layer's writers, read back as weights only.

A checkpoint is a pickle inside a zip.  Unpickling an arbitrary object can run code, so a
checkpoint is read with ``torch.load(weights_only=True)``, which unpickles tensors, numbers,
strings, ``None``, lists and dicts only; one that needs anything else is refused
(:class:`~zbuf_occlude.errors.CheckpointError`) without running it.  The file itself is opened
by :func:`~zbuf_occlude.io.regular_files.open_regular_file`'s rules: a regular file (a FIFO
would block the reader), inside the folder it was named from when the caller knows it
(``within=``), of at most :data:`~zbuf_occlude.io.caps.MAX_CHECKPOINT_BYTES`, and the memory it will take checked
before it is loaded (:func:`zbuf_occlude.resources.check_memory`): what its records inflate to,
from the zip directory, which must hold (:func:`~zbuf_occlude.io.arrays.zip_inflated_bytes`:
torch's zip reader allocates each record's declared size before it reads it, so a small file
whose directory claims gigabytes would reserve them).

Writing goes the other way: :func:`checkpoint_bytes` encodes the state in memory, and the
caller hands the bytes to :meth:`zbuf_occlude.io.owned.OwnedFolder.write_bytes` or
:func:`zbuf_occlude.io.atomic.write_bytes`.

torch is imported inside the functions: ``zbuf_occlude.io`` imports without it.
"""

from __future__ import annotations

import io
import os
import pickle
import zipfile
from pathlib import Path
from typing import Any

from zbuf_occlude.errors import CheckpointError
from zbuf_occlude.io.arrays import zip_inflated_bytes
from zbuf_occlude.io.caps import MAX_CHECKPOINT_BYTES
from zbuf_occlude.io.regular_files import open_regular_file
from zbuf_occlude.resources import check_memory

__all__ = ["checkpoint_bytes", "load_checkpoint"]


def checkpoint_bytes(state: dict[str, Any]) -> bytes:
    """``state`` as the bytes of a PyTorch checkpoint (``torch.save``'s zip format), in memory.

    Parameters
    ----------
    state : dict
        Tensors, numbers, strings, ``None``, lists and dicts only: what :func:`load_checkpoint`
        reads back.

    Returns
    -------
    bytes
        To write with :meth:`~zbuf_occlude.io.owned.OwnedFolder.write_bytes` or
        :func:`~zbuf_occlude.io.atomic.write_bytes`.
    """
    import torch

    buffer = io.BytesIO()
    torch.save(state, buffer)
    return buffer.getvalue()


def load_checkpoint(
    path: str | os.PathLike,
    *,
    keys: tuple[str, ...] = (),
    device: Any = "cpu",
    within: str | os.PathLike | None = None,
    max_bytes: int = MAX_CHECKPOINT_BYTES,
) -> dict:
    """A checkpoint's dict, loaded as weights only: it never runs code.

    Parameters
    ----------
    path : str or PathLike
    keys : tuple of str
        Keys the checkpoint's dict must hold.
    device : str or torch.device
        Where tensors are loaded (``map_location``).
    within : str or PathLike, optional
        The folder ``path`` was named from (a run's checkpoint folder): it must stay inside it,
        links resolved.
    max_bytes : int
        The cap on the file's size (:data:`~zbuf_occlude.io.caps.MAX_CHECKPOINT_BYTES`), checked before a byte is read.

    Returns
    -------
    dict
        The checkpoint's state, its tensors on ``device``.

    Raises
    ------
    CheckpointError
        The file is missing, not a regular file (a FIFO), larger than ``max_bytes``, damaged,
        truncated, not a PyTorch checkpoint, its zip directory claims more than the file can hold
        or records compressed other than by deflate, needs more than weights to load, or lacks
        one of ``keys`` (the message names the file).
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    InsufficientMemoryError
        What its records inflate to is more than the memory available.
    """
    import torch

    path = Path(path)
    fh, size = open_regular_file(path, max_bytes=max_bytes, error=CheckpointError, within=within)
    with fh:
        check_memory(_bytes_to_load(path, fh, size), option=f"the checkpoint {path}", hint="load it on a machine with more memory")
        try:
            state = torch.load(fh, map_location=device, weights_only=True)
        except pickle.UnpicklingError as exc:
            if "weights only" in str(exc).lower() or "weights_only" in str(exc):
                raise CheckpointError(
                    f"{path} needs more than weights to load (pickled objects that could run code); refused: "
                    "zbuf_occlude loads only tensors and plain data from checkpoints"
                ) from None
            raise CheckpointError(f"{path} is damaged or not a PyTorch checkpoint ({exc})") from None
        except OSError as exc:
            raise CheckpointError(f"cannot read the checkpoint {path}: {exc.strerror or exc}") from None
        except (RuntimeError, EOFError, ValueError, zipfile.BadZipFile, KeyError, AttributeError, TypeError) as exc:
            # torch reports a truncated or foreign file as a RuntimeError of its zip reader, an empty one as EOFError
            raise CheckpointError(f"{path} is damaged, truncated or not a PyTorch checkpoint ({type(exc).__name__}: {exc})") from None
    if not isinstance(state, dict):
        raise CheckpointError(f"{path} is not a zbuf_occlude checkpoint (a {type(state).__name__}, not a dict)")
    missing = [k for k in keys if k not in state]
    if missing:
        raise CheckpointError(f"{path} is not a zbuf_occlude checkpoint of this kind: it lacks {', '.join(missing)}")
    return state


def _bytes_to_load(path: Path, fh: Any, size: int) -> int:
    """Bytes torch allocates for the records of the open checkpoint ``fh`` of ``size`` bytes
    (:func:`~zbuf_occlude.io.arrays.zip_inflated_bytes`); ``size`` for a file that is not a zip
    (torch's legacy format, whose storages torch checks against the file itself, or a damaged
    file, which ``torch.load`` names).  ``fh`` is rewound."""
    try:
        zf = zipfile.ZipFile(fh)
    except (zipfile.BadZipFile, EOFError, OSError, ValueError):
        fh.seek(0)
        return size
    try:
        return max(size, zip_inflated_bytes(path, zf, size, error=CheckpointError, writer="torch.save"))
    finally:
        zf.close()  # leaves fh open: zipfile closes only the files it opened itself
        fh.seek(0)
