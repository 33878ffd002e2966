"""Run the CLI or a Python snippet under an address-space limit, as ``prlimit --as`` and batch schedulers set it.

``ulimit -v``, ``prlimit --as=N`` and many batch schedulers limit a process's *address space*
(``RLIMIT_AS``): every mapping counts, used or not, so a read that reserves its cap instead of the
file's size (``fh.read(4 << 30)`` for a 6-byte manifest) fails there although it would never touch
the memory.  These helpers run a command in a child process whose limit is

    footprint + headroom

where the **footprint** is the child's ``VmSize`` (``/proc/self/status``) once the interpreter has
imported what every ``zbuf-occlude`` command imports before it parses its command line: numpy, the
package and its CLI module (:data:`FOOTPRINT_MODULES`), and the modules a test names in
``preload``.  Libraries a command imports later (h5py, numba, trimesh), the threads it starts (a
stack and, for a thread that allocates, a glibc malloc arena of 64 MiB reserved each) and its data
all count against the **headroom** (:data:`HEADROOM_BYTES`, 1.5 GiB), as they count against a
user's limit.  Soft and hard limits are both set, as ``prlimit --as`` does.

**torch** is preloaded (``preload=TORCH``) by every test whose child imports it: what its
libraries map at import is the build's, not ours, and differs by gigabytes between builds (the
CPU wheel about 0.5 GiB; PyPI's default CUDA wheel maps ``libtorch_cuda.so``, cuBLAS, cuDNN and
the rest at import, several GiB of address space, more than the headroom: its import fails with
"failed to map segment from shared object").  The limit is then that mapping, measured in the
child, plus the test's headroom, so that the budget bites our code alike under every build
(tests/test_memory_limit.py holds both).

What is measured, in the child's main process only (its own workers are limited alike, being
forked from it, but not measured here):

* ``peak_bytes``: ``VmPeak``, the largest address space it ever had mapped, which is what
  ``RLIMIT_AS`` is checked against (the footprint included);
* ``peak_rss_bytes``: ``VmHWM``, its largest resident set (``getrusage``'s ``ru_maxrss``);
* ``footprint_bytes`` and ``limit_bytes``: the ``VmSize`` the limit was built on, and the limit.

The child writes them to a file at exit (``atexit``), so that its stdout and stderr are the
command's own; a child that was killed reports nothing and the numbers are None.

Threads count, and some libraries start one per core: Mesa's llvmpipe two per GL context
(``LP_NUM_THREADS``), numba one (``NUMBA_NUM_THREADS``), each reserving some 72 MiB of address
space (an 8 MiB stack and, once it allocates, a 64 MiB glibc malloc arena).  On 2 cores
``generate`` peaks at about 1.25 GiB here; with llvmpipe's threads at 16 (``LP_NUM_THREADS=16``,
as on a 16-core machine) at 3.3 GiB, past this limit, where the worker crashes (SIGSEGV) instead
of raising ``MemoryError``.  What a user under ``prlimit --as`` sees, so the limit is not raised
to hide it.

Use::

    from memory_limit import run_cli_limited
    done = run_cli_limited(["verify", str(dataset)])
    assert done.returncode == 0, done.stderr
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "FOOTPRINT_MODULES", "HEADROOM_BYTES", "HEADROOM_3_GB", "OPEN_DATASET", "TORCH", "Limited", "run_cli_limited", "run_python_limited",
]  # fmt: skip

#: Address space a command may map beyond the interpreter's footprint: 1.5 GiB, what a small job
#: (a few meshes, a 2-sample data set) needs, and far less than the 4 GiB a read reserving the
#: metadata or mesh cap would take.
HEADROOM_BYTES = 1536 << 20
#: Address space beyond the footprint of a process under a user's ``ulimit -v`` of 3 GB: 3 GiB less
#: the footprint (152 MiB measured).
HEADROOM_3_GB = (3 << 30) - (160 << 20)
#: A snippet for :func:`run_python_limited`: open the data set ``argv[1]`` (and read every sample,
#: ``to_arrays()``, when ``argv[2]`` is ``"to_arrays"``); print the refusal and exit 3.
OPEN_DATASET = """
import sys
from zbuf_occlude import OccludedDataset
from zbuf_occlude.errors import ZbufOccludeError
try:
    ds = OccludedDataset(sys.argv[1])
    if sys.argv[2:] == ["to_arrays"]:
        ds.to_arrays()
except ZbufOccludeError as exc:
    print(exc)
    sys.exit(3)
"""
#: What the child imports before its footprint is measured: what ``zbuf-occlude`` imports before
#: it parses a command line (the console script's module pulls in numpy and the package).
FOOTPRINT_MODULES = ("numpy", "zbuf_occlude", "zbuf_occlude.cli.main")
#: ``preload`` of a child that imports torch: its mapping joins the footprint (module docstring).
TORCH = ("torch",)
#: Seconds a child may run before the test fails (a hung command, not a slow machine).
DEFAULT_TIMEOUT_S = 300

# The child: import the footprint, set the limit, run, report at exit.  argv: report path, mode
# ("cli" or "python"), then the CLI's arguments or the snippet and its arguments.
_CHILD = r"""
import atexit, importlib, json, os, resource, sys

def _status():
    out = {}
    with open("/proc/self/status") as fh:
        for line in fh:
            key, _, value = line.partition(":")
            if key in ("VmSize", "VmPeak", "VmHWM"):
                out[key] = int(value.split()[0]) * 1024
    return out

report, mode, headroom, modules, *rest = sys.argv[1:]
for name in filter(None, modules.split(",")):
    importlib.import_module(name)
footprint = _status()["VmSize"]
limit = footprint + int(headroom)
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
pid = os.getpid()

def _report():
    if os.getpid() != pid:  # a forked worker that exits through atexit: not the process measured
        return
    status = _status()
    with open(report, "w") as fh:
        json.dump({"footprint": footprint, "limit": limit, "peak": status["VmPeak"], "rss": status["VmHWM"]}, fh)

atexit.register(_report)
if mode == "cli":
    from zbuf_occlude.cli.main import main
    sys.argv = ["zbuf-occlude", *rest]
    sys.exit(main(rest))
sys.argv = ["-c", *rest[1:]]
exec(compile(rest[0], "<limited snippet>", "exec"), {"__name__": "__main__"})
"""


@dataclass(frozen=True)
class Limited:
    """A child run under an address-space limit (module docstring).

    Attributes
    ----------
    returncode : int
        The child's exit status (negative: killed by that signal).
    stdout, stderr : str
        Its output, decoded as UTF-8.
    peak_bytes : int or None
        ``VmPeak`` of its main process, bytes (None if it did not reach its exit).
    limit_bytes : int or None
        The ``RLIMIT_AS`` it ran under, bytes (footprint + headroom).
    footprint_bytes : int or None
        Its ``VmSize`` after importing :data:`FOOTPRINT_MODULES` and the test's ``preload``, bytes.
    peak_rss_bytes : int or None
        ``VmHWM`` of its main process (its largest resident set), bytes.
    """

    returncode: int
    stdout: str
    stderr: str
    peak_bytes: int | None
    limit_bytes: int | None
    footprint_bytes: int | None = None
    peak_rss_bytes: int | None = None

    def summary(self) -> str:
        """One line: the peak, resident peak, footprint and limit in MiB (for a test's output)."""

        def mib(value: int | None) -> str:
            return "?" if value is None else f"{value / (1 << 20):.0f}"

        return (
            f"VmPeak {mib(self.peak_bytes)} MiB, max RSS {mib(self.peak_rss_bytes)} MiB, "
            f"footprint {mib(self.footprint_bytes)} MiB, limit {mib(self.limit_bytes)} MiB"
        )


def _run_limited(
    mode: str, payload: list[str], *, cwd: str | os.PathLike[str] | None, timeout: float, headroom: int, preload: Sequence[str]
) -> Limited:
    if isinstance(preload, str) or any(not isinstance(name, str) or "," in name or not name for name in preload):
        raise ValueError(f"preload must be a sequence of module names, got {preload!r}")
    with tempfile.TemporaryDirectory(prefix="zo-memory-limit-") as folder:
        report = Path(folder) / "report.json"
        modules = ",".join((*FOOTPRINT_MODULES, *preload))
        command = [sys.executable, "-c", _CHILD, str(report), mode, str(int(headroom)), modules, *payload]
        done = subprocess.run(command, cwd=cwd, capture_output=True, timeout=timeout, check=False)
        numbers = json.loads(report.read_text(encoding="utf-8")) if report.is_file() else {}
    decode = lambda data: data.decode("utf-8", "replace")  # noqa: E731
    return Limited(
        returncode=done.returncode,
        stdout=decode(done.stdout),
        stderr=decode(done.stderr),
        peak_bytes=numbers.get("peak"),
        limit_bytes=numbers.get("limit"),
        footprint_bytes=numbers.get("footprint"),
        peak_rss_bytes=numbers.get("rss"),
    )


def run_cli_limited(
    args: list[str],
    *,
    cwd: str | os.PathLike[str] | None = None,
    timeout: float = DEFAULT_TIMEOUT_S,
    headroom: int = HEADROOM_BYTES,
    preload: Sequence[str] = (),
) -> Limited:
    """``zbuf-occlude ARGS`` in a child limited to its footprint plus ``headroom`` bytes of address space.

    Runs the console script's entry point (``zbuf_occlude.cli.main:main``) in a fresh interpreter.

    Parameters
    ----------
    args : list of str
        The command line after ``zbuf-occlude``.
    cwd : path, optional
        The child's working folder.
    timeout : float
        Seconds before ``subprocess.TimeoutExpired`` is raised.
    headroom : int
        Bytes of address space beyond the footprint (default :data:`HEADROOM_BYTES`).
    preload : sequence of str
        Modules imported, beyond :data:`FOOTPRINT_MODULES`, before the footprint is measured
        (:data:`TORCH` where the command imports torch): their mappings count in the footprint,
        not against the headroom.

    Returns
    -------
    Limited
    """
    return _run_limited("cli", [str(a) for a in args], cwd=cwd, timeout=timeout, headroom=headroom, preload=preload)


def run_python_limited(
    code: str,
    *,
    args: Sequence[str | os.PathLike[str]] = (),
    timeout: float = DEFAULT_TIMEOUT_S,
    headroom: int = HEADROOM_BYTES,
    preload: Sequence[str] = (),
) -> Limited:
    """Run the Python source ``code`` as ``__main__`` in a child limited as :func:`run_cli_limited`'s.

    Parameters
    ----------
    code : str
        A snippet; it may import anything (what it imports beyond :data:`FOOTPRINT_MODULES` and
        ``preload`` counts against the headroom) and exit with ``sys.exit``.
    args : sequence of str or path
        Its ``sys.argv[1:]`` (as strings).
    timeout : float
        Seconds before ``subprocess.TimeoutExpired`` is raised.
    headroom : int
        Bytes of address space beyond the footprint (default :data:`HEADROOM_BYTES`).
    preload : sequence of str
        As :func:`run_cli_limited`'s (:data:`TORCH` where the snippet imports torch).

    Returns
    -------
    Limited
    """
    return _run_limited("python", [code, *map(str, args)], cwd=None, timeout=timeout, headroom=headroom, preload=preload)
