"""``zbuf-occlude generate --protocol ...``: dispatch, outputs and bad options (exit 2 naming the value)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.cli.main import main

CHAIR = str(Path(__file__).resolve().parents[2] / "data" / "samples" / "chair")


def test_modelnet40c_occlusion_from_the_cli(tmp_path, capsys):
    assert main(["generate", CHAIR, "--protocol", "modelnet40-c-occlusion", "--severity", "3", "--out", str(tmp_path)]) == 0
    data = np.load(tmp_path / "data_occlusion_3.npy")
    assert data.shape == (1, 1024, 3) and data.dtype == np.float32
    assert np.load(tmp_path / "label.npy").tolist() == [[8]]  # chair in ModelNet40's shape_names
    assert "1 mesh done" in capsys.readouterr().out  # not "1 meshes"
    # a rerun resumes from the shard and writes the same bytes
    assert main(["generate", CHAIR, "--protocol", "modelnet40-c-occlusion", "--severity", "3", "--out", str(tmp_path)]) == 0
    assert np.array_equal(np.load(tmp_path / "data_occlusion_3.npy"), data)


def test_pcn_from_the_cli(tmp_path):
    assert main(["generate", CHAIR, "--protocol", "pcn", "--out", str(tmp_path)]) == 0
    assert len(list((tmp_path / "shards").glob("pcn_*.h5"))) == 1


def _exit_status(argv):
    try:
        return main(argv)
    except SystemExit as exc:  # argparse's own errors (choices)
        return exc.code


@pytest.mark.parametrize(
    "argv,named",
    [
        (["--protocol", "modelnet40-c-lidar", "--severity", "9"], "9"),
        (["--protocol", "modelnet40-c-lidar", "--severity", "0"], "0"),
        (["--protocol", "pcn", "--severity", "2"], "--severity 2"),
        (["--severity", "4"], "--severity 4"),
        (["--protocol", "nope"], "'nope'"),
        (["--protocol", "depth", "--downsample", "knn"], "'knn'"),
    ],
)
def test_bad_protocol_options_exit_2_naming_the_value(tmp_path, capsys, argv, named):
    assert _exit_status(["generate", CHAIR, "--out", str(tmp_path / "o"), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert named in err
    assert not (tmp_path / "o" / "shards").exists()


def test_modelnet40c_says_when_its_labels_are_not_modelnet40s(tmp_path, caplog):
    import shutil

    mesh = Path(CHAIR) / "train" / "chair_0001.off"
    (tmp_path / "in" / "pedestrian" / "train").mkdir(parents=True)
    shutil.copy(mesh, tmp_path / "in" / "pedestrian" / "train" / "pedestrian_0001.off")
    with caplog.at_level("INFO", logger="zbuf_occlude"):
        assert main(["generate", str(tmp_path / "in"), "--protocol", "modelnet40-c-occlusion", "--severity", "1",
                     "--out", str(tmp_path / "o")]) == 0  # fmt: skip
    said = " ".join(r.getMessage() for r in caplog.records)
    assert "not ModelNet40's 40" in said and "'pedestrian'" in said
    assert (tmp_path / "o" / "shape_names.txt").read_text() == "pedestrian\n" and np.load(tmp_path / "o" / "label.npy").tolist() == [[0]]


def _pcn_complete(out: Path) -> np.ndarray:
    import h5py

    (shard,) = sorted((out / "shards").glob("pcn_*.h5"))
    with h5py.File(shard, "r") as f:
        return f["complete"][()]


def test_protocols_take_generates_up_axis(tmp_path, capsys):
    """``--up`` reaches the protocols (not only the paper's samples)."""
    assert main(["generate", CHAIR, "--protocol", "pcn", "--out", str(tmp_path / "auto")]) == 0
    assert main(["generate", CHAIR, "--protocol", "pcn", "--up", "+y", "--out", str(tmp_path / "y")]) == 0
    auto, y_up = (_pcn_complete(tmp_path / name) for name in ("auto", "y"))
    # PCN's frame is y up: a z-up chair is tallest along y; read as y-up, its old y becomes up
    assert np.ptp(auto[:, 1]) > np.ptp(auto[:, 2])
    assert not np.allclose(np.ptp(auto, axis=0), np.ptp(y_up, axis=0), atol=1e-3)


def test_an_unknown_spelling_of_up_exits_2_naming_it(tmp_path, capsys):
    assert _exit_status(["generate", CHAIR, "--protocol", "pcn", "--up-axis", "y", "--out", str(tmp_path / "o")]) == 2
    assert "--up-axis" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
