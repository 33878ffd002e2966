"""Exception types of zbuf_occlude: one base class, one subclass per cause.

Every error message names the offending file or value and says what to do.
The CLI prints ``ZbufOccludeError`` messages on one line and exits non-zero;
any other exception is a bug in zbuf_occlude.
"""

from __future__ import annotations

__all__ = [
    "ZbufOccludeError",
    "MeshLoadError",
    "InvalidInputError",
    "CameraError",
    "BackendUnavailable",
    "OutputError",
    "RegistryError",
    "UnknownOptionError",
    "PaddedSamplesWarning",
    "CameraPlacementWarning",
    "UnsafePathError",
    "DatasetFormatError",
    "CheckpointError",
    "ShardChecksumError",
    "InsufficientMemoryError",
    "DatasetBusy",
    "ArgumentTypeError",
]


class ZbufOccludeError(Exception):
    """Base class of every error raised on purpose by zbuf_occlude."""


class MeshLoadError(ZbufOccludeError):
    """A mesh file is missing, unreadable, of unknown format, empty or non-finite."""


class InvalidInputError(ZbufOccludeError, ValueError):
    """An argument has the wrong shape, dtype, range or contains NaN/inf."""


class CameraError(ZbufOccludeError, ValueError):
    """A camera is ill-posed: inside the object, degenerate pose, bad intrinsics."""


class BackendUnavailable(ZbufOccludeError, RuntimeError):
    """No OpenGL context (EGL, OSMesa) or an optional library (pyrender, Embree) is missing."""


class OutputError(ZbufOccludeError, OSError):
    """An output path cannot be written (unwritable folder, disk full)."""


class RegistryError(ZbufOccludeError, RuntimeError):
    """A visibility method registered twice under one name, or with an unknown capability (a bug in a plugin)."""


class UnknownOptionError(ZbufOccludeError, TypeError):
    """A keyword a visibility method does not take (a misspelt ``tolerence``); a ``TypeError``,
    as Python's own for an unexpected keyword argument."""


class UnsafePathError(InvalidInputError):
    """A path named by metadata (a data set's card, manifest, records or file lists, a farm
    task folder, a mesh name) would leave its folder: absolute, ``..``, or through a symlink."""


class DatasetFormatError(InvalidInputError):
    """A data set's metadata or shard does not match its schema (the message names the file and field)."""


class CheckpointError(InvalidInputError):
    """A checkpoint cannot be loaded as weights only: damaged, not a checkpoint, or it needs code to unpickle."""


class ShardChecksumError(InvalidInputError):
    """A shard's bytes differ from the SHA-256 the farm recorded for it in the manifest."""


class InsufficientMemoryError(InvalidInputError):
    """A job would need more memory than is available; the message names the option."""


class DatasetBusy(OutputError):
    """Another live process holds the lock of this data set (or of this shard)."""


class ArgumentTypeError(ZbufOccludeError, TypeError):
    """An API argument of the wrong kind (a file name where a mesh goes, a tuple where a
    :class:`~zbuf_occlude.Camera` goes, text where points go); a ``TypeError``, as Python's own."""


class PaddedSamplesWarning(UserWarning):
    """Some samples hold repeated points: fewer points were visible than a sample holds."""


class CameraPlacementWarning(UserWarning):
    """A camera where the CLI would not put one: inside the object's bounding box, or so far
    that the object spans less than a pixel (a cloud in its file's units, a camera inside the
    mesh); the message names the camera's distance and the object's extent."""
