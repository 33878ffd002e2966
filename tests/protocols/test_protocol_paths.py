"""A protocol's outputs name each mesh relative to the input root, never by its absolute path: the
same meshes in two places give the same files, and a run recorded by earlier versions (absolute
paths in ``protocol.json``) still resumes."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.dataset.layout import PROTOCOL_FILE
from zbuf_occlude.io.owned import LEDGER_FILE
from zbuf_occlude.protocols import ProtocolOptions, get_protocol, read_arrays_h5, run_protocol

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
MESH = "chair/train/chair_0001.off"
#: Each protocol with options that keep it quick.
OPTIONS = {
    "modelnet40-c-occlusion": ProtocolOptions(severity=1),
    "pcn": ProtocolOptions(seed=5),
    "depth": ProtocolOptions(views="0:0,30:90", resolution=64),
}


def _files(out: Path) -> dict[str, object]:
    """Every file of ``out``: HDF5 shards as their arrays and attributes, other files as bytes."""
    files = {}
    for path in sorted(p for p in out.rglob("*") if p.is_file()):
        if path.suffix == ".h5":
            files[path.relative_to(out).as_posix()] = {
                k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in read_arrays_h5(path).items()
            }
        else:
            files[path.relative_to(out).as_posix()] = path.read_bytes()
    return files


@pytest.mark.parametrize("protocol", sorted(OPTIONS))
def test_the_same_mesh_in_two_places_gives_the_same_files_naming_no_folder_of_either(protocol, tmp_path):
    outs = []
    for place in ("a", "b/deeper"):
        (tmp_path / place / "meshes" / MESH).parent.mkdir(parents=True)
        shutil.copyfile(SAMPLES / MESH, tmp_path / place / "meshes" / MESH)
        out = tmp_path / place / "out"
        run = run_protocol(get_protocol(protocol), [tmp_path / place / "meshes"], out, OPTIONS[protocol], progress=False)
        assert run.done == 1 and not run.failures
        for path in out.rglob("*"):
            assert not path.is_file() or str(tmp_path).encode() not in path.read_bytes(), path
        outs.append(out)
    assert _files(outs[0]) == _files(outs[1])
    record = next(outs[0].glob("protocol*.json"))  # ModelNet40-C: one record per corruption and severity
    recorded = json.loads(record.read_text())
    assert recorded["objects"] == [["chair/train/chair_0001", MESH]] and recorded["source"] == "meshes"


def test_a_run_recorded_with_absolute_paths_resumes(tmp_path):
    meshes = tmp_path / "meshes"
    (meshes / MESH).parent.mkdir(parents=True)
    shutil.copyfile(SAMPLES / MESH, meshes / MESH)
    out, protocol, options = tmp_path / "out", get_protocol("pcn"), OPTIONS["pcn"]
    assert run_protocol(protocol, [meshes], out, options, progress=False).done == 1
    recorded = json.loads((out / PROTOCOL_FILE).read_text())
    del recorded["source"]
    recorded["objects"] = [["chair/train/chair_0001", str(meshes / MESH)]]  # as earlier versions wrote it
    (out / PROTOCOL_FILE).write_text(json.dumps(recorded))
    (out / LEDGER_FILE).unlink()  # earlier versions kept no ledger
    again = run_protocol(protocol, [meshes], out, options, progress=False)
    assert (again.resumed, again.done) == (1, 0)
