"""The main commands under an address-space limit (``prlimit --as``, ``ulimit -v``, a batch scheduler's).

Each runs in a child limited to its footprint plus 1.5 GiB (:mod:`memory_limit`) and must exit 0:
a read that reserves a file's cap rather than its size (4 GiB for a manifest) cannot pass.  One
module-scoped farm builds the tiny data set that ``verify``, ``export`` and the DataLoader read.
Each test prints its child's peak (``-s`` shows them): VmPeak, max RSS, footprint and limit.
"""

from __future__ import annotations

import json
import shutil
import textwrap
from pathlib import Path

import pytest
from conftest import SAMPLE_MESHES
from memory_limit import HEADROOM_BYTES, Limited, run_cli_limited, run_python_limited

from zbuf_occlude.sensors.airborne import AirborneScanner
from zbuf_occlude.sensors.beam import Beam
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
    _passed("OccludedDataset + DataLoader", run_python_limited(code))
