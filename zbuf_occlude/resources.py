"""Memory a job will need, estimated before anything is allocated, and the memory there is.

``generate --points 1000000000`` used to grow to 23 GB and be killed by the OOM killer
(issue 9, defect 7).  The CLI and the farm call :func:`estimate_job_memory` and
:func:`check_memory` up front; :func:`zbuf_occlude.geometry.sampling.sample_faces` checks its own
allocation too.  The estimate is linear in each size, with per-item costs measured on
this code (peak resident memory of one object's job, see the constants); it is an
estimate, so the check refuses only what clearly cannot fit.

Memory available is the smallest of ``MemAvailable`` (``/proc/meminfo``), the room
left under this process's cgroup memory limit (v1 or v2), if one is set, and the address
space left under its ``RLIMIT_AS`` (``ulimit -v``, ``prlimit --as``), if one is set; elsewhere
psutil's ``virtual_memory().available`` when psutil is installed; else unknown, and
nothing is refused.
"""

from __future__ import annotations

import logging
import numbers
from dataclasses import dataclass, field
from pathlib import Path

from zbuf_occlude.errors import InsufficientMemoryError, InvalidInputError

__all__ = [
    "cpu_flags",
    "MemoryEstimate",
    "estimate_job_memory",
    "available_memory",
    "address_space_limit",
    "check_memory",
    "format_bytes",
    "BYTES_PER_DENSE_POINT",
    "BYTES_PER_SAMPLE_POINT",
    "BYTES_PER_HELD_SAMPLE_POINT",
    "BYTES_PER_PIXEL",
    "BYTES_PER_FACE",
    "BYTES_PER_WORKER",
    "MIN_CHECKED_BYTES",
]

log = logging.getLogger(__name__)

# Per-item costs: slopes of the peak resident memory (ru_maxrss) of occlude_object on
# data/samples chair_0001 (2,234 faces) with Mesa llvmpipe, between two sizes of one
# parameter (e.g. 1e5 and 2e6 dense points), rounded up.  Measured 2026-11-21.
#: Dense cloud: sampling's peak (corners of each point's face, (N, 3, 3) float64, plus
#: points, face index and barycentrics): 136 B per point by tracemalloc, 133 B by RSS.
BYTES_PER_DENSE_POINT = 136
#: Drawing one sample: indices, padding and the float64 gather, per point, transient.
BYTES_PER_SAMPLE_POINT = 16
#: A sample kept until it is written (float32 points, int64 face index, the shard's
#: stacked copy), per point.
BYTES_PER_HELD_SAMPLE_POINT = 32
#: Render target (RG32F colour + 32-bit depth, in host memory on llvmpipe) and readback.
BYTES_PER_PIXEL = 16
#: A loaded mesh with its renderer and Embree scene: 865 B per face measured on a
#: 327,680-face icosphere.
BYTES_PER_FACE = 900
#: One more worker process (Python, numpy, trimesh, an OpenGL context): ~250 MB each.
BYTES_PER_WORKER = 256 * 2**20
#: Allocations smaller than this are not checked by library functions (reading
#: /proc costs more than they risk).
MIN_CHECKED_BYTES = 64 * 2**20


def format_bytes(n: float) -> str:
    """``1536`` → ``"1.5 KiB"``; binary units, three significant digits."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.3g} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


@dataclass(frozen=True)
class MemoryEstimate:
    """The memory a job needs, by the option that causes it.

    Attributes
    ----------
    parts : dict of str to int
        Bytes per cause, keyed by the option's name (``"--points"``, ``"--dense-points"``,
        ``"--resolution"``, ``"--workers"``, ``"mesh faces"``).
    values : dict of str to int
        The value each option was given, for the message.
    """

    parts: dict[str, int] = field(default_factory=dict)
    values: dict[str, object] = field(default_factory=dict)

    @property
    def total(self) -> int:
        """Bytes, all causes together."""
        return int(sum(self.parts.values()))

    @property
    def largest(self) -> str | None:
        """The option that costs the most (None for an empty estimate)."""
        return max(self.parts, key=self.parts.__getitem__) if self.parts else None

    def describe(self) -> str:
        """``"--points 1,000,000,000: 44.7 GiB; --dense-points 100,000: 13 MiB"``, largest first."""
        items = sorted(self.parts.items(), key=lambda kv: -kv[1])
        return "; ".join(f"{k} {_fmt_value(self.values.get(k))}: {format_bytes(v)}" for k, v in items if v)


def _fmt_value(value: object) -> str:
    return f"{value:,}" if isinstance(value, int) else str(value)


def estimate_job_memory(
    *,
    points: int = 0,
    samples_per_view: int = 1,
    samples_held: int | None = None,
    dense_points: int = 0,
    resolution: int | tuple[int, int] = 0,
    faces: int = 0,
    workers: int = 1,
) -> MemoryEstimate:
    """Peak memory of occluding objects: one object per worker, all workers at once.

    Parameters
    ----------
    points : int
        Points per sample (``--points``).
    samples_per_view : int
        Samples drawn per pose; one is built at a time.
    samples_held : int, optional
        Samples kept in memory until the object is written: ``samples_per_view`` for
        per-pose writers (npz, ply), ``views * samples_per_view`` for one file per object
        (h5, the farm's dense shards).  Default ``samples_per_view``.
    dense_points : int
        Dense cloud per object (``--dense-points``).
    resolution : int or (width, height)
        Image size in pixels (``--resolution``).
    faces : int
        Faces of the largest mesh, if known (0: not counted).
    workers : int
        Worker processes, each running one object at a time.

    Returns
    -------
    MemoryEstimate
        Bytes by option (see the module's constants for the per-item costs).

    Raises
    ------
    InvalidInputError
        A negative count.
    """
    width, height = (resolution, resolution) if isinstance(resolution, numbers.Integral) else tuple(resolution)
    held = samples_per_view if samples_held is None else samples_held
    counts = {"points": points, "samples_per_view": samples_per_view, "samples_held": held,
              "dense_points": dense_points, "width": width, "height": height, "faces": faces, "workers": workers}  # fmt: skip
    bad = {k: v for k, v in counts.items() if not isinstance(v, numbers.Integral) or isinstance(v, bool) or v < 0}
    if bad or workers < 1:
        raise InvalidInputError(f"memory estimate needs non-negative integer sizes and workers >= 1, got {bad or counts}")
    points, samples_per_view, held, dense_points, width, height, faces, workers = (
        int(v) for v in (points, samples_per_view, held, dense_points, width, height, faces, workers)
    )
    resolution = width if width == height else (width, height)
    per_worker = {
        "--points": points * (BYTES_PER_SAMPLE_POINT + BYTES_PER_HELD_SAMPLE_POINT * max(held, 1 if samples_per_view else 0)),
        "--dense-points": dense_points * BYTES_PER_DENSE_POINT,
        "--resolution": width * height * BYTES_PER_PIXEL,
        "mesh faces": faces * BYTES_PER_FACE,
    }
    parts = {k: v * workers for k, v in per_worker.items()}
    parts["--workers"] = (workers - 1) * BYTES_PER_WORKER
    values: dict[str, object] = {
        "--points": points if held <= 1 else f"{points:,} (x {held:,} samples held)",
        "--dense-points": dense_points,
        "--resolution": resolution if isinstance(resolution, int) else f"{width}x{height}",
        "mesh faces": faces,
        "--workers": workers,
    }
    if workers > 1:
        values = {k: (f"{_fmt_value(v)} (x {workers} workers)" if k != "--workers" else v) for k, v in values.items()}
    return MemoryEstimate(parts, values)


def _read_int(path: Path) -> int | None:
    try:
        text = path.read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def cpu_flags(cpuinfo: Path = Path("/proc/cpuinfo")) -> frozenset[str]:
    """The instruction-set flags of this machine's first CPU as Linux lists them (``avx2``, ``fma``,
    ``avx512f``...); empty where ``/proc/cpuinfo`` cannot be read (another system)."""
    try:
        for line in cpuinfo.read_text(encoding="ascii", errors="replace").splitlines():
            if line.startswith("flags"):
                return frozenset(line.split(":", 1)[-1].split())
    except OSError:
        pass
    return frozenset()


def _stat_value(path: Path, key: str) -> int:
    try:
        for line in path.read_text().splitlines():
            tokens = line.split()
            if len(tokens) >= 2 and tokens[0] == key and tokens[1].isdigit():
                return int(tokens[1])
    except OSError:
        pass
    return 0


#: A cgroup limit at or above this is "no limit" (v1 writes 2^63 rounded to a page).
_NO_LIMIT = 2**60


def _cgroup_room(root: Path = Path("/sys/fs/cgroup"), proc_cgroup: Path = Path("/proc/self/cgroup")) -> int | None:
    """Bytes left under the tightest cgroup memory limit of this process; None if none."""
    try:
        lines = proc_cgroup.read_text().splitlines()
    except OSError:
        return None
    rooms = []
    for line in lines:
        _, controllers, rel = line.split(":", 2)
        if controllers == "":  # v2: limit, usage and reclaimable cache per level
            base, limit_name, usage_name, cache_name = root, "memory.max", "memory.current", "inactive_file"
        elif "memory" in controllers.split(","):  # v1
            base = root / "memory"
            limit_name, usage_name, cache_name = "memory.limit_in_bytes", "memory.usage_in_bytes", "total_inactive_file"
        else:
            continue
        # Inside a container the namespaced path may not exist under the mount: then the
        # mount's root is this process's cgroup.  Limits of ancestors apply too.
        here = base / rel.lstrip("/")
        levels = [here, *here.parents] if here.is_dir() else [base]
        for level in levels:
            if not str(level).startswith(str(base)):
                break
            limit = _read_int(level / limit_name)
            if limit is not None and limit < _NO_LIMIT:
                usage = _read_int(level / usage_name) or 0
                cache = _stat_value(level / "memory.stat", cache_name)
                rooms.append(max(limit - usage + cache, 0))
    return min(rooms) if rooms else None


def address_space_limit() -> int | None:
    """This process's soft ``RLIMIT_AS`` (``ulimit -v``, ``prlimit --as``), bytes; None if it has none or off POSIX."""
    try:
        import resource
    except ImportError:  # not on POSIX
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    return None if soft == resource.RLIM_INFINITY else soft


def _address_space_room(status: Path = Path("/proc/self/status")) -> int | None:
    """Bytes of address space left under this process's ``RLIMIT_AS``; None if it has none.

    ``ulimit -v``, ``prlimit --as`` and many batch schedulers limit the address space, not the
    resident memory: what counts is the limit less what is mapped now (``VmSize``).
    """
    limit = address_space_limit()
    if limit is None or limit >= _NO_LIMIT:
        return None
    return max(limit - _stat_value(status, "VmSize:") * 1024, 0)


def available_memory() -> tuple[int, str] | None:
    """Memory this process can still allocate, and where the number comes from.

    Returns
    -------
    (bytes, source) or None
        The smallest of ``MemAvailable``, the room under the cgroup limit and the address space
        left under ``RLIMIT_AS`` (``ulimit -v``), with ``source`` naming which; psutil's figure
        off Linux; None when unknown.
    """
    candidates = []
    meminfo = _stat_value(Path("/proc/meminfo"), "MemAvailable:")
    if meminfo:
        candidates.append((meminfo * 1024, "MemAvailable in /proc/meminfo"))
    room = _cgroup_room()
    if room is not None:
        candidates.append((room, "room under the cgroup memory limit"))
    address_room = _address_space_room()
    if address_room is not None:
        candidates.append((address_room, "address space left under the process's limit (ulimit -v)"))
    if not candidates:
        try:
            import psutil
        except ImportError:
            return None
        candidates.append((int(psutil.virtual_memory().available), "psutil.virtual_memory().available"))
    return min(candidates)


def check_memory(
    estimate: MemoryEstimate | int,
    option: str | None = None,
    *,
    available: int | None = None,
    hint: str | None = None,
) -> None:
    """Refuse a job that needs more memory than is available, before it allocates.

    The one memory check of the package, made before the work wherever an option's value or an
    input's size sets an allocation (a cloud's points, a shard's rows, a ledger's lines).

    Parameters
    ----------
    estimate : MemoryEstimate or int
        From :func:`estimate_job_memory`, or bytes.
    option : str, optional
        The option, argument or input to name (``"--points"``, ``"the ledger L (3,000 bytes)"``;
        default: the estimate's largest part).
    available : int, optional
        Bytes available (default :func:`available_memory`; unknown → no check).
    hint : str, optional
        What to do, appended to the message (default: "lower OPTION").

    Raises
    ------
    InsufficientMemoryError
        ``estimate`` exceeds the memory available; the message names the option and its
        value, the estimate and the memory available.
    """
    total = estimate.total if isinstance(estimate, MemoryEstimate) else int(estimate)
    if available is None:
        if total < MIN_CHECKED_BYTES:
            return
        found = available_memory()
        if found is None:
            log.debug("memory available is unknown; not checking an estimate of %s", format_bytes(total))
            return
        available, source = found
    else:
        source = "given"
    if total <= available:
        return
    if isinstance(estimate, MemoryEstimate):
        option = option or estimate.largest
        detail = f" ({estimate.describe()})"
    else:
        detail = ""
    name = option or "this job"
    raise InsufficientMemoryError(
        f"{name} needs about {format_bytes(total)} of memory{detail}, more than the {format_bytes(available)} "
        f"available ({source}); {hint or f'lower {name}'}"
    )
