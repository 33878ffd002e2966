"""The main commands under an address-space limit (``prlimit --as``, ``ulimit -v``, a batch scheduler's).

Each runs in a child limited to its footprint plus 1.5 GiB (:mod:`memory_limit`) and must exit 0:
a read that reserves a file's cap rather than its size (4 GiB for a manifest) cannot pass.  One
module-scoped farm builds the tiny data set that ``verify``, ``export`` and the DataLoader read.
Each test prints its child's peak (``-s`` shows them): VmPeak, max RSS, footprint and limit.
"""

from __future__ import annotations

import json
import os
import shutil
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import SAMPLE_MESHES
from memory_limit import HEADROOM_3_GB, HEADROOM_BYTES, TORCH, Limited, run_cli_limited, run_python_limited

from zbuf_occlude.sensors.patterns.airborne import AirborneScanner
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.kinds import sensor_to_json

#: The farm's meshes: two of the shipped samples, one a class.
CLASSES = "chair,table"
#: A small farm: two poses, one sample each, few points, a small image; one worker process.
FARM = ["--classes", CLASSES, "--views", "0:0,30:90", "--samples-per-view", "1", "--points", "64", "--dense-points", "2000",
        "--resolution", "64", "--workers", "1", "--no-progress"]  # fmt: skip
#: An airborne scanner small enough for a quick scan: a 2° beam of 7 sub-rays, up to 3 returns, 100 m up.
ALS = AirborneScanner("limit-als", swath_deg=20.0, pulse_rate_hz=2000.0, line_rate_hz=20.0, altitude_m=100.0, speed_mps=10.0,
                      beam=Beam(wavelength_nm=1064.0, divergence_deg=2.0, footprint_rays=7, max_returns=3, range_resolution_m=1.0))  # fmt: skip


def _passed(name: str, done: Limited) -> None:
    """Assert ``done`` exited 0 under its limit, and print its peak."""
    print(f"\n{name}: {done.summary()}")
    assert done.returncode == 0, f"{name} exited {done.returncode} under {done.limit_bytes} bytes of address space:\n{done.stderr[-3000:]}"
    assert done.peak_bytes is not None and done.peak_bytes <= done.limit_bytes, done.summary()


@pytest.fixture(scope="module")
def farmed(tmp_path_factory) -> tuple[Path, Limited]:
    """A two-object data set farmed under the limit from the shipped samples, and that run."""
    root = tmp_path_factory.mktemp("memory_limit")
    done = run_cli_limited(["farm", str(SAMPLE_MESHES), "--out", str(root / "ds"), *FARM])
    return root / "ds", done


@pytest.fixture(scope="module")
def dataset(farmed) -> Path:
    """The data set of :func:`farmed`, which must have been written."""
    path, done = farmed
    if done.returncode != 0:
        pytest.fail(f"the farm under the limit failed, nothing to read: {done.stderr[-2000:]}")
    return path


def test_a_six_byte_file_read_under_a_32_gib_cap_reserves_six_bytes(tmp_path: Path) -> None:
    # read(cap + 1) allocated the cap first: MemoryError for 6 bytes under any limit below 32 GiB
    six = tmp_path / "six.txt"
    six.write_bytes(b"abcdef")
    code = f"from zbuf_occlude.io.regular_files import read_regular_file\nassert read_regular_file({str(six)!r}, max_bytes=32 << 30) == b'abcdef'"
    done = run_python_limited(code)
    _passed("read_regular_file", done)
    assert done.peak_bytes < done.footprint_bytes + HEADROOM_BYTES // 2, done.summary()  # nothing near a cap was mapped


@pytest.mark.slow
def test_farm_runs_under_the_limit(farmed) -> None:
    _, done = farmed
    _passed("farm", done)
    assert "2 done" in done.stdout, done.stdout


@pytest.mark.slow
def test_a_resumed_farm_into_the_same_out_runs_under_the_limit(dataset: Path, tmp_path: Path) -> None:
    # a run stopped before its last object's record was written: the rerun reads the plan, the
    # records, the card and the manifest of the first, renders that object and rewrites the manifest
    out = tmp_path / "ds"
    shutil.copytree(dataset, out)
    sorted((out / "records").glob("*.json"))[-1].unlink()
    done = run_cli_limited(["farm", str(SAMPLE_MESHES), "--out", str(out), *FARM])
    _passed("farm (resumed)", done)
    assert "2 done (1 from an earlier run), 0 failed" in done.stdout, done.stdout


@pytest.mark.slow
def test_verify_runs_under_the_limit(dataset: Path) -> None:
    _passed("verify", run_cli_limited(["verify", str(dataset), "--no-progress"]))


@pytest.mark.slow
def test_export_to_pointnet_h5_and_a_re_export_run_under_the_limit(dataset: Path, tmp_path: Path) -> None:
    args = ["export", str(dataset), "--to", "pointnet-h5", "--out", str(tmp_path / "export"), "--no-progress"]
    _passed("export", run_cli_limited(args))
    _passed("re-export", run_cli_limited(args))  # reads the export's ledger and lock, replaces what it wrote
    assert sorted(p.suffix for p in (tmp_path / "export").glob("*.h5")), list((tmp_path / "export").iterdir())


@pytest.mark.slow
def test_generate_runs_under_the_limit(tmp_path: Path) -> None:
    meshes = [str(SAMPLE_MESHES / "chair" / "train" / "chair_0001.off"), str(SAMPLE_MESHES / "stool" / "train" / "stool_0002.off")]
    done = run_cli_limited(["generate", *meshes, "--out", str(tmp_path / "gen"), "--views", "0:0,30:90", "--points", "64",
                            "--dense-points", "2000", "--resolution", "64", "--no-progress"])  # fmt: skip
    _passed("generate", done)


@pytest.fixture(scope="module")
def scanned(tmp_path_factory) -> tuple[Path, Limited]:
    """LAS scans of a box flown over by :data:`ALS`, written by ``scan --format las`` under the limit, and that run."""
    root = tmp_path_factory.mktemp("memory_limit_scan")
    (root / "als.json").write_text(json.dumps(sensor_to_json(ALS)))
    done = run_cli_limited(["scan", "box", "--sensor", str(root / "als.json"), "--extents", "6,6,10", "--distance", "2", "--samples", "2",
                            "--format", "las", "--no-progress", "--out", str(root / "scans")])  # fmt: skip
    return root / "scans", done


@pytest.mark.slow
def test_scan_to_las_runs_under_the_limit(scanned) -> None:
    scans, done = scanned
    _passed("scan --format las", done)
    assert len(list(scans.glob("*.las"))) == 2, list(scans.iterdir())


@pytest.mark.slow
def test_fit_sensor_on_our_own_las_scans_runs_under_the_limit(scanned, tmp_path: Path) -> None:
    scans, done = scanned
    assert done.returncode == 0, done.stderr[-2000:]
    out = tmp_path / "fitted.json"
    fitted = run_cli_limited(["fit-sensor", str(scans), "--sensor", "riegl-q1560", "--altitude", "100", "--bootstrap", "20",
                              "--out", str(out)])  # fmt: skip
    _passed("fit-sensor", fitted)
    assert json.loads(out.read_text())["fit"]["returns"]["altitude_m"] == 100.0


@pytest.mark.slow
def test_the_data_set_through_torchs_dataloader_under_the_limit(dataset: Path) -> None:
    pytest.importorskip("torch")
    code = textwrap.dedent(
        f"""
        import torch.utils.data
        import zbuf_occlude as zo
        ds = zo.OccludedDataset({str(dataset)!r})
        loader = torch.utils.data.DataLoader(ds, batch_size=2, shuffle=True, num_workers=2)  # workers forked under the limit
        seen = sum(len(points) for points, label, meta in loader)
        assert seen == len(ds) == 4, (seen, len(ds))
        """
    )
    _passed("OccludedDataset + DataLoader", run_python_limited(code, preload=TORCH))  # torch's libraries: the footprint


# -- the limit itself: footprint (torch's libraries included) plus the headroom ----------------------------
#: A module whose import maps 3 GiB of address space (read-only, never touched), as PyPI's CUDA build
#: of torch maps its libraries at import: more than any headroom here.
_FAT_IMPORT = "import mmap\nRESERVED = mmap.mmap(-1, 3 << 30, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS, prot=mmap.PROT_READ)\n"
#: The headroom of the helper's own tests: small, so that the allocations that probe it are quick.
_PROBE_HEADROOM = 256 << 20
#: In the child: the limit it runs under, then its VmSize before and after importing argv[1] (preloaded
#: or not), then whether an allocation of argv[2] bytes fits.
_PROBE = """
import importlib, resource, sys
def vm_size():
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmSize:"))
print(*resource.getrlimit(resource.RLIMIT_AS))
before = vm_size()
importlib.import_module(sys.argv[1])
print(before, vm_size())
try:
    block = bytearray(int(sys.argv[2]))
    print("allocated")
except MemoryError:
    print("MemoryError")
"""


@pytest.fixture(params=["fat", pytest.param("torch", marks=pytest.mark.slow)])  # importing torch takes seconds
def preloaded(request, tmp_path: Path, monkeypatch) -> str:
    """A module that maps much at import: one of 3 GiB (as the CUDA build of torch), or torch as installed."""
    if request.param == "torch":
        pytest.importorskip("torch")
        return "torch"
    (tmp_path / "fat_import.py").write_text(_FAT_IMPORT)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(tmp_path), os.environ.get("PYTHONPATH")])))
    return "fat_import"


def _probe(module: str, allocate: int) -> tuple[Limited, list[list[int | str]]]:
    done = run_python_limited(_PROBE, args=[module, str(allocate)], headroom=_PROBE_HEADROOM, preload=(module,), timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return done, [[int(w) if w.isdecimal() else w for w in line.split()] for line in done.stdout.splitlines()]


def test_the_limit_is_the_footprint_with_the_preloaded_libraries_plus_the_headroom(preloaded: str) -> None:
    done, ((soft, hard), (before, after), (fits,)) = _probe(preloaded, _PROBE_HEADROOM // 2)
    assert soft == hard == done.limit_bytes == done.footprint_bytes + _PROBE_HEADROOM, done.summary()
    # the library was mapped before the footprint was measured: importing it again maps nothing
    assert done.footprint_bytes <= before == after < done.footprint_bytes + _PROBE_HEADROOM // 4, (done.summary(), before, after)
    if preloaded == "fat_import":
        assert done.footprint_bytes > 3 << 30, done.summary()
    assert fits == "allocated", done.summary()


def test_the_headroom_still_bites_with_the_preloaded_libraries(preloaded: str) -> None:
    done, (_, _, (fits,)) = _probe(preloaded, _PROBE_HEADROOM + (64 << 20))
    assert fits == "MemoryError", done.summary()


def test_preload_takes_module_names() -> None:
    for bad in ("torch", ["torch,numpy"], [""]):
        with pytest.raises(ValueError, match="preload must be a sequence of module names"):
            run_python_limited("pass", preload=bad)


# -- a point-set cloud beyond the cap under a user's 3 GB limit ------------------------------------------
#: Points of the held-out cloud: under the 10-million-point cap it was read against, over the one that
#: holds ``generate`` to a minute on two cores.
_HELD_OUT_POINTS = 9_900_000
#: In the child: ``zbuf-occlude ARGV``, with every read of an HDF5 ``/data`` in this process written
#: to stderr (the plan runs here; the clouds are read in spawned workers, which a refused plan never starts).
_SPIED_CLI = """
import sys
import h5py
from zbuf_occlude.cli.main import main
read = h5py.Dataset.__getitem__
def spied(self, key):
    if self.name == "/data":
        print("READ /data", file=sys.stderr)
    return read(self, key)
h5py.Dataset.__getitem__ = spied
sys.exit(main(sys.argv[1:]))
"""


def test_a_cloud_beyond_the_point_cap_is_refused_from_its_header_in_one_line_under_a_3_gb_limit(tmp_path: Path) -> None:
    """9.9 million points in a small gzip-compressed PointNet file, ``generate`` under ``ulimit -v`` 3 GB:
    refused from the header before the array is read (no worker started), the line naming the points,
    the cap and what occluding them would need; the 3 GB never come near."""
    from zbuf_occlude.defaults import MAX_POINT_SET_POINTS

    assert _HELD_OUT_POINTS > MAX_POINT_SET_POINTS
    path = tmp_path / "scan.h5"
    with h5py.File(path, "w") as f:  # a regular pattern: 119 MB of float32 in about 0.5 MB
        data = f.create_dataset(
            "data", (1, _HELD_OUT_POINTS, 3), np.float32, compression="gzip", compression_opts=1, chunks=(1, 1 << 20, 3)
        )
        for start in range(0, _HELD_OUT_POINTS, 1 << 20):
            data[0, start : start + (1 << 20)] = 0.25
        f["label"] = np.zeros((1, 1), np.uint8)
    done = run_python_limited(_SPIED_CLI, args=["generate", path, "--out", tmp_path / "out", "--no-progress"], headroom=HEADROOM_3_GB)
    print(f"\ngenerate (refused): {done.summary()}")
    errors = [line for line in done.stderr.splitlines() if line.startswith("zbuf-occlude: error:")]
    assert done.returncode != 0 and len(errors) == 1, done.stderr[-3000:]
    assert f"{path}: its clouds hold {_HELD_OUT_POINTS:,} points each, more than the {MAX_POINT_SET_POINTS:,} accepted" in errors[0]
    assert "GiB of memory" in errors[0] and "minutes" in errors[0] and "Traceback" not in done.stderr, done.stderr[-3000:]
    assert "READ /data" not in done.stderr and "done" not in done.stdout, done.stdout + done.stderr[-3000:]
    assert done.peak_bytes is not None and done.peak_bytes <= done.limit_bytes, done.summary()


# -- the scanner's inputs, refused in one line under the limit as without it ----------------------------------------

_SECRET = "ya29.not-a-real-token-but-a-canary"


def _scanner_case(tmp_path: Path, case: str) -> tuple[list[str], int, str]:
    """``scan``'s command line for a hostile or careless input, the exit status and a piece of its one-line refusal."""
    street = str(Path(__file__).resolve().parents[1] / "data" / "scenes" / "street.json")
    out = ["--no-progress", "--out", str(tmp_path / "o")]
    if case == "class map linked to a token file":
        (tmp_path / "home").mkdir()
        (tmp_path / "home" / "token.json").write_text(json.dumps({"access_token": _SECRET}))
        (tmp_path / "work").mkdir()
        (tmp_path / "work" / "classes.json").symlink_to(tmp_path / "home" / "token.json")
        return ["scan", street, "--format", "las", "--class-map", str(tmp_path / "work" / "classes.json"), *out], 2, "classes.json"
    if case == "trajectory turning a half turn":
        columns = "time_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg"
        (tmp_path / "drive.csv").write_text(f"{columns}\n0,0,0,1.8,0,0,0\n1,1,0,1.8,0,0,270\n")
        return ["scan", street, "--trajectory", str(tmp_path / "drive.csv"), *out], 2, "the attitude turns 180° or more"
    if case == "gps start losing the microsecond":
        return ["scan", street, "--format", "las", "--gps-start", "1e17", *out], 2, "--gps-start 1e17"
    if case == "vertical crs":
        return ["scan", street, "--format", "las", "--frame", "world", "--crs", "EPSG:5703", *out], 2, "a scan needs a projected CRS"
    if case == "power noise past a receiver's":
        return ["scan", street, "--power-noise", "1e308", *out], 2, "--power-noise"
    assert case == "footprint cast on a depth camera"
    return ["scan", street, "--sensor", "kinect-v1", "--footprint-cast", "exact", *out], 2, "--footprint-cast"


@pytest.mark.parametrize(
    "case",
    ["class map linked to a token file", "trajectory turning a half turn", "gps start losing the microsecond", "vertical crs",
     "power noise past a receiver's", "footprint cast on a depth camera"],
)  # fmt: skip
def test_the_scanners_inputs_are_refused_in_one_line_under_the_limit(tmp_path: Path, case: str) -> None:
    if case == "vertical crs":
        pytest.importorskip("pyproj", reason="the crs extra")
    argv, status, piece = _scanner_case(tmp_path, case)
    done = run_cli_limited(argv)
    err = done.stderr.strip()
    assert done.returncode == status and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert piece in err and _SECRET not in err and "ya29" not in err, err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())
