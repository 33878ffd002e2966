"""Faults around the farm (issue 9): two writers on one data set, tampered shards, killed parents.

Real subprocesses and signals, small shipped meshes (``data/samples``), few poses and points.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from zbuf_occlude.dataset.layout import CARD_FILE, LOCK_FILE, MANIFEST_FILE
from zbuf_occlude.dataset.reader import OccludedDataset
from zbuf_occlude.errors import DatasetBusy
from zbuf_occlude.farm import FarmParams, merge_farm, run_farm
from zbuf_occlude.farm.config import RunOptions
from zbuf_occlude.farm.lock import farm_lock, task_lock_path

REPO_ROOT = Path(__file__).resolve().parents[2]
#: The three smallest shipped meshes (96–400 faces).
MESHES = ("sofa/test/sofa_0681.off", "stool/train/stool_0002.off", "monitor/train/monitor_0001.off")
PARAMS = FarmParams(views="0:0,40:90,-40:200", samples_per_view=2, n_points=64, dense_points=1024, resolution=64)
CLI_PARAMS = ["--views", "fibonacci:40", "--samples-per-view", "2", "--points", "64", "--dense-points", "1024",
              "--resolution", "64", "--no-progress"]  # fmt: skip


@pytest.fixture
def tree(tmp_path, sample_meshes_dir) -> Path:
    root = tmp_path / "in"
    for rel in MESHES:
        dst = root / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(sample_meshes_dir / rel, dst)
    return root


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(REPO_ROOT)}


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "zbuf_occlude", *args]


def _wait_for(predicate, proc: subprocess.Popen | None = None, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert proc is None or proc.poll() is None, "the process ended before the condition held"
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _host() -> str:
    from filelock._identity import host_name  # what filelock writes into its lock files

    return host_name()


# -- defect 1: two farms on one --out ---------------------------------------------------------------
@pytest.mark.slow
def test_second_farm_on_the_same_out_refuses_and_names_the_holder(tree, tmp_path):
    """The issue's scenario: pause the first run mid-write, run a second to the end, resume the first."""
    out = tmp_path / "ds"
    first = subprocess.Popen(_cli("farm", str(tree), "--out", str(out), *CLI_PARAMS), env=_env(), cwd=tmp_path)
    try:
        _wait_for(lambda: list((out / "records").glob("*.json")), first)
        first.send_signal(signal.SIGSTOP)
        second = subprocess.run(
            _cli("farm", str(tree), "--out", str(out), *CLI_PARAMS), env=_env(), cwd=tmp_path,
            capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert second.returncode == 2, second.stderr
        assert f"pid {first.pid} on host {socket.gethostname()} since 20" in second.stderr
        assert "Traceback" not in second.stderr
    finally:
        first.send_signal(signal.SIGCONT)
    assert first.wait(timeout=300) == 0
    card = json.loads((out / CARD_FILE).read_text())
    assert card["n_objects_ok"] == len(MESHES)
    lines = [json.loads(line) for line in (out / MANIFEST_FILE).read_text().splitlines()]
    assert [r["status"] for r in lines] == ["ok"] * len(MESHES)
    assert len(OccludedDataset(out)) == card["n_samples"] > 0
    assert not (out / LOCK_FILE).exists()  # released at the end


def test_a_lock_left_by_a_dead_process_is_taken_over(tree, tmp_path):
    out = tmp_path / "ds"
    out.mkdir()
    (out / LOCK_FILE).write_text(f"{_dead_pid()}\n{_host()}\n")
    summary = run_farm(tree, out, params=PARAMS, options=RunOptions(progress=False))
    assert summary.finished and summary.done == len(MESHES)
    assert not (out / LOCK_FILE).exists()


@pytest.mark.slow
def test_a_lock_of_another_host_is_never_broken(tree, tmp_path):
    out = tmp_path / "ds"
    out.mkdir()
    (out / LOCK_FILE).write_text("4242\nnode17.cluster\n")
    with pytest.raises(DatasetBusy, match=r"pid 4242 on host node17\.cluster since .*delete .*\.zbuf_occlude\.lock"):
        run_farm(tree, out, params=PARAMS, options=RunOptions(progress=False))
    assert (out / LOCK_FILE).exists() and not (out / "records").exists()  # nothing written


def test_stale_temp_cleanup_spares_temps_of_live_processes(tree, tmp_path):
    out = tmp_path / "ds"
    run_farm(tree, out, params=PARAMS, options=RunOptions(progress=False))
    from zbuf_occlude.io.atomic import _host_tag

    alive = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        live_tmp = out / "shards" / f".train_000001.h5.{alive.pid}-{_host_tag()}-abcd1234.tmp"
        dead_tmp = out / "shards" / f".train_000001.h5.{_dead_pid()}-{_host_tag()}-efgh5678.tmp"
        legacy_tmp = out / "records" / ".000001.json.k2j3h4.tmp"
        for tmp in (live_tmp, dead_tmp, legacy_tmp):
            tmp.write_bytes(b"partial")
        run_farm(tree, out, params=PARAMS, options=RunOptions(progress=False))
        assert live_tmp.exists()  # another process may be writing it right now
        assert not dead_tmp.exists() and not legacy_tmp.exists()
    finally:
        alive.kill()
        alive.wait()


def test_temp_names_are_unique_per_process_and_name_their_writer(tmp_path):
    from zbuf_occlude.io.atomic import atomic_path, temp_owner

    with atomic_path(tmp_path / "a.h5") as t1, atomic_path(tmp_path / "a.h5") as t2:
        assert t1 != t2
        owner = temp_owner(t1.name)
        assert owner is not None and owner.target == "a.h5" and owner.pid == os.getpid()
        t1.write_bytes(b"1")
        t2.write_bytes(b"2")


@pytest.mark.slow
def test_shard_tasks_run_at_once_but_not_beside_a_whole_run(tree, tmp_path):
    out = tmp_path / "ds"
    out.mkdir()
    # a live task 0/2 holds its lock (another process of the same array)
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from zbuf_occlude.farm.lock import farm_lock; "
         f"cm = farm_lock({str(out)!r}, (0, 2)); cm.__enter__(); print('held', flush=True); time.sleep(60)"],
        env=_env(), stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        summary = run_farm(tree, out, params=PARAMS, options=RunOptions(shard=(1, 2), progress=False))  # runs beside task 0
        assert summary.done == len(MESHES[1::2]) and not summary.finished
        # only farm-merge writes the data-set-wide files
        assert not (out / MANIFEST_FILE).exists() and not (out / CARD_FILE).exists()
        assert not (out / "train_files.txt").exists() and not (out / "shape_names.txt").exists()
        with pytest.raises(DatasetBusy, match=f"task 0/2.*pid {holder.pid}"):
            run_farm(tree, out, params=PARAMS, options=RunOptions(progress=False))
        with pytest.raises(DatasetBusy, match=f"task 0/2.*pid {holder.pid}"):
            run_farm(tree, out, params=PARAMS, options=RunOptions(shard=(0, 2), progress=False))
        with pytest.raises(DatasetBusy, match=f"task 0/2.*pid {holder.pid}"):
            merge_farm([out])  # a merge waits for every task
    finally:
        holder.kill()
        holder.wait()
    assert task_lock_path(out, (0, 2)).exists()  # left by the killed holder, broken by the next run
    with farm_lock(out):  # a whole-data-set holder keeps tasks out
        with pytest.raises(DatasetBusy, match="the data set"):
            run_farm(tree, out, params=PARAMS, options=RunOptions(shard=(0, 2), progress=False))
    run_farm(tree, out, params=PARAMS, options=RunOptions(shard=(0, 2), progress=False))
    assert not task_lock_path(out, (0, 2)).exists()


# -- defect 9: a shard overwritten in place with the same size ------------------------------------
def test_a_shard_changed_in_place_is_caught_by_the_reader_and_redone_by_resume(tree, tmp_path):
    import h5py
    import numpy as np

    from zbuf_occlude.errors import ShardChecksumError

    out = tmp_path / "ds"
    run_farm(tree, out, params=PARAMS, options=RunOptions(progress=False))
    before, _ = OccludedDataset(out).to_arrays()
    shard = out / "shards" / "test_000001.h5"
    size = shard.stat().st_size
    with h5py.File(shard, "r+") as f:  # what the issue did: same size, other bytes
        f["data"][0] = np.float32(3.4e38)
    assert shard.stat().st_size == size

    ds = OccludedDataset(out)
    with pytest.raises(ShardChecksumError, match=r"shards/test_000001\.h5 was changed"):
        ds.to_arrays()
    with pytest.raises(ShardChecksumError, match="test_000001"):
        [ds[i] for i in range(len(ds))]

    summary = run_farm(tree, out, params=PARAMS, options=RunOptions(progress=False))
    assert summary.resumed == len(MESHES) - 1 and summary.done == len(MESHES)  # only the changed one redone
    after, _ = OccludedDataset(out).to_arrays()
    assert np.array_equal(before, after) and np.abs(after).max() <= 1.0


# -- defect 5: orphaned workers --------------------------------------------------------------------
def _children(pid: int) -> set[int]:
    kids: set[int] = set()
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            kids |= {int(k) for k in (task / "children").read_text().split()}
        except OSError:
            pass
    return kids


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")  # a zombie has exited; only its parent's reaping is left


VIEWS_LONG = "fibonacci:900"
#: The pool-farm tests need the run to last ~10 s; the z-buffer's speed on llvmpipe gives that
#: (``auto`` picks the faster threaded Embree path here and would finish before the signal).
METHOD_LONG = "zbuffer"


def _start_pool_farm(tree: Path, out: Path, cwd: Path) -> tuple[subprocess.Popen, set[int]]:
    """A farm with --workers 2 on many poses (about 10 s on one core), once both workers are rendering."""
    proc = subprocess.Popen(
        _cli("farm", str(tree), "--out", str(out), "--workers", "2", "--method", METHOD_LONG, *CLI_PARAMS[:1], VIEWS_LONG,
             *CLI_PARAMS[2:]),
        env=_env(), cwd=cwd, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    _wait_for(lambda: len(_children(proc.pid)) >= 3, proc)  # two workers and the resource tracker
    time.sleep(1)  # let them load and start rendering (the run lasts several seconds more)
    assert proc.poll() is None
    return proc, _children(proc.pid)


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux /proc to find the workers")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_workers_do_not_outlive_a_killed_parent(tree, tmp_path, sig):
    out = tmp_path / "ds"
    proc, workers = _start_pool_farm(tree, out, tmp_path)
    assert workers and all(_alive(w) for w in workers)
    proc.send_signal(sig)
    rc = proc.wait(timeout=60)
    _wait_for(lambda: not any(_alive(w) for w in workers), timeout_s=10)  # within seconds
    if sig == signal.SIGTERM:  # handled like Ctrl-C: a clean, resumable stop
        assert rc == 143, proc.stderr.read()
        assert "interrupted; run the same command again to resume" in proc.stderr.read()
        assert not (out / LOCK_FILE).exists()
        summary = run_farm(
            tree,
            out,
            params=FarmParams(**{**PARAMS.to_dict(), "views": VIEWS_LONG, "method": METHOD_LONG}),
            options=RunOptions(progress=False),
        )
        assert summary.finished and summary.done == len(MESHES) and summary.failed == 0
        assert not list(out.rglob(".*.tmp"))


# -- skipped inputs are recorded and end the run with status 1 (defect 12's slot in the farm) ----
def test_skipped_inputs_are_recorded_in_the_card_and_give_status_1(tree, tmp_path):
    from zbuf_occlude.mesh.inputs.plan import discover_objects

    out = tmp_path / "ds"
    locked = str(tree / "locked")  # a ready plan's caller's skip: a folder of the input root
    options = RunOptions(progress=False, skipped=[(locked, "permission denied")])
    summary = run_farm(discover_objects(tree), out, params=PARAMS, options=options)
    assert summary.done == len(MESHES) and summary.exit_status == 1
    assert f"SKIPPED   {locked}: permission denied" in summary.format()  # for the person running it: as given
    card = json.loads((out / CARD_FILE).read_text())
    assert card["skipped_inputs"] == [{"path": "locked", "reason": "permission denied"}]  # the data set's: relative
    assert run_farm(discover_objects(tree), out, params=PARAMS, options=RunOptions(progress=False)).exit_status == 0


# -- a long native call, a killed worker ----------------------------------------------------------
#: Imported by every Python process started with its folder first on PYTHONPATH (the CLI and its
#: spawned workers): makes ``load_mesh`` of the mesh named by ZO_TEST_HOLD a long native call.
_HOLD_HOOK = """
import os
if os.environ.get("ZO_TEST_HOLD"):
    import signal, time
    import zbuf_occlude.mesh.load as mesh  # the farm's worker imports load_mesh from here when it runs

    _load_mesh = mesh.load_mesh

    def load_mesh(source, *args, **kwargs):
        name, marker = os.environ["ZO_TEST_HOLD"].split(os.pathsep)
        if name in str(source):
            # what a long Embree or GL call does to Python: signals wait until it returns
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM, signal.SIGINT})
            with open(marker + ".part", "w") as f:  # whole or absent: the test reads the pid once the file exists
                f.write(str(os.getpid()))
            os.replace(marker + ".part", marker)
            time.sleep(600)
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGTERM, signal.SIGINT})
        return _load_mesh(source, *args, **kwargs)

    mesh.load_mesh = load_mesh
"""


def _hold_env(tmp_path: Path, name: str) -> tuple[dict[str, str], Path]:
    """Environment whose processes hold forever (signals blocked) in the load of mesh ``name``."""
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(_HOLD_HOOK)
    marker = tmp_path / "holding"
    env = {**_env(), "PYTHONPATH": os.pathsep.join([str(hook), str(REPO_ROOT)]), "ZO_TEST_HOLD": f"{name}{os.pathsep}{marker}"}
    return env, marker


@pytest.mark.slow
def test_sigterm_inside_a_long_native_call_stops_generate_within_seconds(tree, tmp_path):
    out = tmp_path / "gen"
    env, marker = _hold_env(tmp_path, "stool_0002")
    proc = subprocess.Popen(_cli("generate", str(tree), "--out", str(out), *CLI_PARAMS[:-1]), env=env, cwd=tmp_path,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        _wait_for(marker.exists, proc)
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(timeout=30)  # the held call lasts 600 s: only a stop from outside it ends the run
    finally:
        proc.kill()
    err = proc.stderr.read()
    assert rc == 143, err
    assert "interrupted; run the same command again to resume" in err and "Traceback" not in err
    assert not (out / LOCK_FILE).exists()
    held = int(marker.read_text())
    _wait_for(lambda: not _alive(held), timeout_s=10)  # the worker did not outlive the stop
    done = subprocess.run(_cli("generate", str(tree), "--out", str(out), *CLI_PARAMS[:-1]), env=_env(), cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr
    card = json.loads((out / CARD_FILE).read_text())
    assert card["n_objects_ok"] == len(MESHES)
    assert not list(out.rglob(".*.tmp"))


@pytest.mark.slow
def test_a_killed_farm_worker_fails_only_its_object(tree, tmp_path):
    out = tmp_path / "ds"
    env, marker = _hold_env(tmp_path, "stool_0002")
    proc = subprocess.Popen(_cli("farm", str(tree), "--out", str(out), "--workers", "2", *CLI_PARAMS), env=env,
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        _wait_for(marker.exists, proc)
        os.kill(int(marker.read_text()), signal.SIGKILL)  # what the out-of-memory killer does
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        proc.kill()
    assert proc.returncode == 1, stderr
    assert "Traceback" not in stderr and "BrokenProcessPool" not in stderr
    lines = {r["name"]: r for r in map(json.loads, (out / MANIFEST_FILE).read_text().splitlines())}
    assert [r["status"] for r in lines.values()].count("ok") == len(MESHES) - 1  # the others were finished
    failed = lines["stool/train/stool_0002"]
    assert failed["status"] == "failed" and "SIGKILL" in failed["error"], failed
    assert "FAILED" in stdout and "stool_0002" in stdout and "SIGKILL" in stdout
    assert not (out / LOCK_FILE).exists()
    summary = run_farm(tree, out, params=FarmParams(**{**PARAMS.to_dict(), "views": "fibonacci:40"}), options=RunOptions(progress=False))
    assert summary.resumed == len(MESHES) - 1 and summary.done == len(MESHES) and summary.exit_status == 0
    assert not list(out.rglob(".*.tmp"))


# -- issue 15: a mesh of many identical faces ---------------------------------------------------------
def _tetra_with_copies(m: int):
    import numpy as np
    import trimesh

    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]) - 0.25
    faces = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]] + [[0, 2, 1]] * m  # the base, m more times
    return trimesh.Trimesh(v, np.array(faces), process=False)


def test_identical_faces_cost_the_embree_oracle_one_face_per_group():
    """The work per point around m copies of one face does not grow with m (it was O(m): a mesh of
    300,000 copies ran for minutes), and the answer is the exact one."""
    import numpy as np

    import zbuf_occlude as zo
    from zbuf_occlude.visibility.oracle_embree import _EmbreeScene, occluded_embree
    from zbuf_occlude.visibility.oracle_numpy import occluded_numpy

    pairs_per_face = []
    for m in (10, 500):
        mesh = _tetra_with_copies(m)
        scene = _EmbreeScene(mesh.vertices, mesh.faces)
        k, g = scene.faces_around(np.arange(len(mesh.faces)))
        pairs_per_face.append(len(g) / len(mesh.faces))
        assert set(g.tolist()) == {0, 1, 2, 3}  # one face stands for the m + 1 copies of the base
        points, face_index = zo.sample_surface(mesh, count=1500, seed=1)
        for eye in ([0.2, 0.1, -3.0], [3.0, 2.0, 1.0], [2.0, 2.0, -0.25]):  # below the base, above, edge-on
            exact = occluded_numpy(mesh.triangles, points, np.array(eye), face_index=face_index)
            stats: dict[str, int] = {}
            got = occluded_embree(mesh, points, np.array(eye), face_index=face_index, stats=stats)
            assert np.array_equal(got, exact), eye
            assert stats["casts"] <= 2 * len(points)  # not a re-cast per copy
    assert pairs_per_face == [9.0, 9.0]  # three corners, three faces around each


def test_identical_faces_enter_embree_fast_once():
    """embree-fast's rays see one face per group of identical faces (a ray grazing m copies tested
    all m), and the answer does not change with the copies."""
    import numpy as np

    import zbuf_occlude as zo
    from zbuf_occlude.visibility.cpu_zbuffer import _MeshData
    from zbuf_occlude.visibility.embree_fast import _Scene

    for m in (10, 500):
        assert _Scene(_tetra_with_copies(m)).n_faces_in_bvh == 4
        assert _MeshData(_tetra_with_copies(m)).raster_ids.tolist() == [0, 1, 2, 3]  # the pre-pass's buffer too
    one, many = _tetra_with_copies(0), _tetra_with_copies(200)
    points, face_index = zo.sample_surface(one, count=2000, seed=3)
    for elevation_deg, azimuth_deg in ((-60.0, 20.0), (30.0, 45.0), (0.0, 45.0)):  # below the base, above, edge-on
        camera = zo.camera_on_sphere(elevation_deg=elevation_deg, azimuth_deg=azimuth_deg, radius=4.0)
        a = zo.visible_mask(one, points, camera, face_index=face_index, method="embree-fast")
        b = zo.visible_mask(many, points, camera, face_index=face_index, method="embree-fast")
        assert np.array_equal(a, b)
