"""The zbuf-occlude command line: generate, resume, failures, validate, info."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from zbuf_occlude.cli.main import main
from zbuf_occlude.io.clouds import read_h5, read_npz


@pytest.fixture
def two_meshes(tmp_path, sample_meshes_dir):
    root = tmp_path / "in"
    for cls, name in (("sofa", "sofa_0681"), ("monitor", "monitor_0001")):
        src = next(sample_meshes_dir.glob(f"{cls}/*/{name}.off"))
        dst = root / cls / "train" / src.name
        dst.parent.mkdir(parents=True)
        shutil.copy(src, dst)
    return root


ARGS = ["--views", "30:45,-40:200", "--points", "128", "--samples-per-view", "2", "--resolution", "256", "--dense-points", "5000"]


@pytest.mark.slow
def test_generate_writes_one_file_per_sample_and_resumes(tmp_path, two_meshes, capsys):
    out = tmp_path / "out"
    assert main(["generate", str(two_meshes), "--out", str(out), "--format", "npz", *ARGS]) == 0
    files = sorted(out.rglob("*.npz"))
    assert len(files) == 2 * 2 * 2
    cloud = read_npz(files[0])
    assert cloud.points.shape == (128, 3) and cloud.class_name in ("sofa", "monitor")
    mtimes = {f: f.stat().st_mtime_ns for f in files}
    assert main(["generate", str(two_meshes), "--out", str(out), "--format", "npz", *ARGS]) == 0  # resume: nothing to redo
    assert {f: f.stat().st_mtime_ns for f in files} == mtimes
    assert "2 meshes done, 0 failed" in capsys.readouterr().out


@pytest.mark.slow
def test_a_bad_mesh_is_reported_and_skipped(tmp_path, two_meshes, capsys):
    bad = two_meshes / "sofa" / "train" / "broken.off"
    bad.write_text("OFF\n3 1 0\n0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n")
    out = tmp_path / "out"
    assert main(["generate", str(two_meshes), "--out", str(out), "--format", "npz", *ARGS]) == 1
    captured = capsys.readouterr()
    assert "broken.off" in captured.err and "1 failed" in captured.out
    assert len(list(out.rglob("*.npz"))) == 8  # the good meshes are all there


@pytest.mark.slow
def test_generate_h5_and_ply(tmp_path, two_meshes):
    out = tmp_path / "h5"
    assert main(["generate", str(two_meshes), "--out", str(out), "--format", "h5", *ARGS]) == 0
    d = read_h5(out / "occluded_train.h5")  # both meshes are in train/ folders
    assert not (out / "occluded_test.h5").exists()
    assert d["data"].shape == (8, 128, 3) and sorted(set(d["label"].tolist())) == [0, 1]
    assert list(d["shape_names"]) == ["monitor", "sofa"]
    out = tmp_path / "ply"
    assert main(["generate", str(two_meshes), "--out", str(out), "--format", "ply", *ARGS]) == 0
    assert len(list(out.rglob("*.ply"))) == 8


def test_validate_prints_agreement_per_pose(two_meshes, tmp_path, capsys):
    csv_path = tmp_path / "v.csv"
    code = main(
        [
            "validate",
            str(two_meshes),
            "--views",
            "30:45",
            "--dense-points",
            "3000",
            "--methods",
            "zbuffer,zbuffer-tolerance",
            "--csv",
            str(csv_path),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0 and "zbuffer: mean agreement" in out and csv_path.exists()
    accuracy = [float(line.split()[4]) for line in out.splitlines() if " zbuffer " in line]
    assert len(accuracy) == 2 and min(accuracy) > 99.0


def test_info_names_the_gl_renderer(capsys):
    assert main(["info"]) == 0
    assert "GL renderer" in capsys.readouterr().out


def test_user_errors_are_one_line_and_exit_2(tmp_path, capsys):
    assert main(["generate", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("zbuf-occlude: error:") and "\n" not in err
    assert main(["validate", "--views", "bogus"]) == 2


# -- exit codes ----------------------------------------------------------------------------
def test_validate_exits_1_when_a_mesh_fails(tmp_path, two_meshes, capsys):
    bad = two_meshes / "sofa" / "train" / "broken.off"
    bad.write_text("OFF\n3 1 0\n0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n")
    code = main(["validate", str(two_meshes), "--views", "30:45", "--dense-points", "500", "--resolution", "128"])
    captured = capsys.readouterr()
    assert code == 1
    assert "FAILED" in captured.err and "broken.off" in captured.err
    # the good meshes were still scored
    assert sum(" auto " in line for line in captured.out.splitlines()) == 2


def test_interrupt_exits_130_with_a_resume_hint(tmp_path, two_meshes, monkeypatch, capsys):
    from zbuf_occlude.farm import run

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(run, "run_in_workers", interrupted)  # generate's parent waits on its worker process
    assert main(["generate", str(two_meshes), "--out", str(tmp_path / "o"), *ARGS]) == 130
    assert "interrupted" in capsys.readouterr().err
    monkeypatch.setattr(run, "run_farm", interrupted)  # the farm command imports run_farm from run when it runs
    assert main(["farm", str(two_meshes), "--out", str(tmp_path / "f"), "--no-progress"]) == 130


@pytest.mark.parametrize(
    "argv",
    [
        ["farm", "{missing}", "--out", "{tmp}/f"],
        ["farm", "{meshes}", "--out", "{tmp}/f", "--shard", "5/2"],
        ["farm", "{meshes}", "--out", "{tmp}/f", "--workers", "0"],
        ["farm", "{meshes}", "--out", "{tmp}/f", "--views", "bogus"],
        ["farm-merge", "{missing}"],
    ],
    ids=["missing-root", "bad-shard", "no-workers", "bad-views", "merge-missing"],
)
def test_farm_errors_through_main_exit_2_on_one_line(tmp_path, two_meshes, capsys, argv):
    argv = [a.format(missing=tmp_path / "nope", tmp=tmp_path, meshes=two_meshes) for a in argv]
    assert main([*argv, "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("zbuf-occlude: error:") and "\n" not in err


@pytest.mark.slow
def test_python_dash_m_runs_the_cli_and_passes_its_exit_status(tmp_path):
    import os
    import subprocess
    import sys

    from zbuf_occlude import __version__

    def run(*argv):
        return subprocess.run(
            [sys.executable, "-m", "zbuf_occlude", *argv], check=False, capture_output=True, text=True, timeout=300, env=os.environ
        )

    out = run("--version")
    assert out.returncode == 0 and out.stdout.strip() == f"zbuf-occlude {__version__}"
    out = run("generate", str(tmp_path / "nope"), "--out", str(tmp_path / "o"))
    assert out.returncode == 2 and out.stderr.startswith("zbuf-occlude: error:")
    assert run("no-such-command").returncode == 2  # argparse's usage error


def test_generate_without_a_path_finds_the_shipped_samples() -> None:
    # README's first command, `zbuf-occlude generate --out out`, runs on data/samples of the checkout
    from zbuf_occlude.cli.main import SAMPLE_MESHES

    assert SAMPLE_MESHES == Path(__file__).resolve().parents[2] / "data" / "samples"
    assert any(SAMPLE_MESHES.rglob("*.off"))


def _no_memory(*args, **kwargs):
    raise MemoryError("Unable to allocate 7.45 GiB for an array with shape (1000000000,) and data type float64")


def test_out_of_memory_is_one_line_naming_what_and_which_file_and_exits_1(sample_meshes_dir, monkeypatch, capsys):
    # validate loads the chair, then samples its surface: sampling's memory check runs out of memory
    monkeypatch.setattr("zbuf_occlude.geometry.sampling.check_memory", _no_memory)
    chair = min(sample_meshes_dir.glob("chair/*/*.off"))
    assert main(["validate", str(chair), "--views", "30:45", "--dense-points", "100", "--methods", "oracle"]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    assert err.startswith("zbuf-occlude: error: `validate` ran out of memory"), err
    assert "zbuf_occlude.geometry.sampling.sample_faces" in err and f"on {chair}" in err and "7.45 GiB" in err, err


def test_out_of_memory_without_a_file_names_the_command(monkeypatch, capsys):
    monkeypatch.setattr("zbuf_occlude.render.context.context_info", _no_memory)
    assert main(["info"]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("zbuf-occlude: error: `info` ran out of memory (Unable to allocate"), err


# -- a refused run leaves no empty --out behind -----------------------------------------------------------------
@pytest.mark.parametrize(
    ("argv", "out"),
    [
        (["farm", "{tmp}/no_such_meshes", "--out", "{out}"], "o"),
        (["farm", "{samples}", "--classes", "no_such_class", "--out", "{out}"], "a/b/c"),  # its parents too
        (["generate", "{samples}/chair", "--resolution", "1000000", "--out", "{out}"], "o"),  # beyond the GL's maximum
    ],
)
def test_a_refused_run_leaves_no_empty_out_folder(tmp_path, sample_meshes_dir, capsys, argv, out):
    argv = [a.format(tmp=tmp_path, samples=sample_meshes_dir, out=tmp_path / "runs" / out) for a in argv]
    (tmp_path / "runs").mkdir()
    assert main(argv) == 2
    assert "zbuf-occlude: error:" in capsys.readouterr().err
    assert list((tmp_path / "runs").iterdir()) == []  # runs/ existed before: kept, and empty


def test_a_refused_run_keeps_an_out_that_existed_or_holds_a_file(tmp_path, monkeypatch):
    from zbuf_occlude.errors import InvalidInputError
    from zbuf_occlude.farm import run as farm_run

    existed = tmp_path / "existed"
    existed.mkdir()
    assert main(["farm", str(tmp_path / "no_such_meshes"), "--out", str(existed)]) == 2
    assert existed.is_dir()

    def refuse_after_writing(root, out, *args, **kwargs):
        (Path(out) / "shards").mkdir(parents=True)
        if Path(out).name == "keep":
            (Path(out) / "shards" / "part.h5").write_bytes(b"")
        raise InvalidInputError("refused after writing")

    monkeypatch.setattr(farm_run, "run_farm", refuse_after_writing)
    assert main(["farm", str(tmp_path), "--out", str(tmp_path / "keep")]) == 2
    assert (tmp_path / "keep" / "shards" / "part.h5").is_file()  # written: never removed
    assert main(["farm", str(tmp_path), "--out", str(tmp_path / "empty_tree")]) == 2
    assert not (tmp_path / "empty_tree").exists()  # only empty folders: removed
