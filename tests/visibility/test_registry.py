"""The method registry declares capabilities; nothing outside it tests method names."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest
import trimesh

import zbuf_occlude
from zbuf_occlude.errors import InvalidInputError, RegistryError, ZbufOccludeError
from zbuf_occlude.experiments.compare.run import _sweep_jobs
from zbuf_occlude.geometry.samples import object_key
from zbuf_occlude.pipeline import PoseDraws, occlude_object
from zbuf_occlude.visibility import registry
from zbuf_occlude.visibility.registry import available_methods, method_info, register

PACKAGE = Path(zbuf_occlude.__file__).parent


@pytest.fixture
def scratch_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    """Methods registered in a test vanish afterwards."""
    monkeypatch.setattr(registry, "_METHODS", dict(registry._METHODS))
    monkeypatch.setattr(registry, "_INFO", dict(registry._INFO))


def _everything_visible(mesh, points, camera, *, face_index=None, **options):
    return np.ones(len(points), dtype=bool)


def test_builtin_capabilities() -> None:
    image_space = {m for m in available_methods() if method_info(m).takes_resolution}
    assert image_space == {"auto", "zbuffer", "zbuffer-exact", "zbuffer-tolerance", "naive-zbuffer"}
    assert {m for m in available_methods() if method_info(m).takes_grid} == {"og"}
    assert {m for m in available_methods() if method_info(m).grid_of == "og"} == {"og16", "og32", "og64", "og128"}
    assert {m for m in available_methods() if method_info(m).session is not None} == {"zbuffer", "zbuffer-exact", "embree-fast", "auto"}
    assert {m for m in available_methods() if method_info(m).extra} == {"open3d-hpr", "open3d-raycast"}
    assert {"oracle", "oracle-numpy", "zbuffer-exact", "paper-exact", "paper-pruned-plane"} <= {
        m for m in available_methods() if method_info(m).exact
    }
    assert not method_info("paper-pruned").exact and not method_info("og32").exact
    with pytest.raises(InvalidInputError, match="no-such-method"):
        method_info("no-such-method")


def test_registry_errors_are_ours(scratch_registry: None) -> None:
    register("x-test")(_everything_visible)
    with pytest.raises(RegistryError, match="registered twice"):
        register("x-test")(lambda *a, **k: None)
    with pytest.raises(RegistryError, match="unknown method capabilities"):
        register("y-test", takes_colour=True)
    assert issubclass(RegistryError, ZbufOccludeError) and issubclass(RegistryError, RuntimeError)


def test_a_new_method_is_one_function_and_one_register(scratch_registry: None) -> None:
    """A method declaring ``session`` is run resident by occlude_object; one declaring
    ``takes_resolution`` is swept by compare; no other edit."""
    sessions: list[int] = []

    class CountingSession:
        def __init__(self, mesh, points, face_index):
            sessions.append(len(points))
            self.n, self.calls, self.released = len(points), 0, False

        def visible(self, camera, **options):
            self.calls += 1
            return np.ones(self.n, dtype=bool)

        def release(self):
            self.released = True

    register("x-resident", takes_resolution=True, session=CountingSession)(_everything_visible)
    mesh = trimesh.creation.box()
    poses = [(0.0, 0.0), (30.0, 90.0), (-45.0, 200.0)]
    out = list(occlude_object(mesh, poses, key=object_key("box"), draws=PoseDraws(n_points=8, samples_per_view=1), method="x-resident"))
    assert len(out) == 3 and all(v.all() for _, v, _ in out)
    assert len(sessions) == 1  # points uploaded once for all poses
    jobs = _sweep_jobs(["x-resident", "oracle"], [64, 128], [8])
    assert [(m, s, p) for m, s, p, _ in jobs] == [("x-resident", "resolution", 64), ("x-resident", "resolution", 128)]
    assert [(m, p) for m, s, p, _ in _sweep_jobs(["og32", "og64"], [], [8, 16])] == [("og", 8), ("og", 16)]


def _compared_names(tree: ast.AST, names: set[str]) -> list[tuple[int, str]]:
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            # only comparisons of something named like a method ("auto" is also a data-set
            # format in real_scans, for example)
            if "method" not in ast.unparse(node).lower():
                continue
            for part in [node.left, *node.comparators]:
                consts = part.elts if isinstance(part, (ast.Tuple, ast.List, ast.Set)) else [part]
                for c in consts:
                    if isinstance(c, ast.Constant) and c.value in names:
                        found.append((node.lineno, c.value))
    return found


def test_no_module_special_cases_a_method_name() -> None:
    """``if method == "zbuffer"`` / ``m in ("og", ...)`` outside the methods' own modules is
    what the capabilities replace."""
    names = set(available_methods())
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.parent.name == "visibility":
            continue  # a method's own module may name itself
        for line, name in _compared_names(ast.parse(path.read_text(encoding="utf-8")), names):
            offenders.append(f"{path.relative_to(PACKAGE)}:{line} compares with {name!r}")
    assert not offenders, "\n".join(offenders)


def test_name_check_sees_a_comparison() -> None:
    tree = ast.parse('if method == "zbuffer":\n    pass\nif args.methods in ("og", "x"):\n    pass\nif fmt == "og":\n    pass\n')
    assert _compared_names(tree, {"zbuffer", "og"}) == [(1, "zbuffer"), (3, "og")]


# -- keywords: a misspelt option is an error, never the default ---------------------------------
def test_every_method_refuses_an_unknown_keyword_naming_it():
    from zbuf_occlude.visibility.registry import check_keywords, method_keywords

    for name in available_methods():
        with pytest.raises(TypeError, match=r"'tolerence'"):
            check_keywords(name, {"tolerence": 0.5})
        check_keywords(name, {k: None for k in method_keywords(name)})  # its own keywords pass


def test_visible_mask_and_sessions_refuse_typos():
    mesh = trimesh.creation.icosphere(subdivisions=1)
    points, fi = zbuf_occlude.sample_surface(mesh, 50, seed=0)
    cam = zbuf_occlude.camera_on_sphere(10.0, 20.0, resolution=64)
    for method in ("auto", "embree-fast", "oracle", "zbuffer-exact", "paper-exact"):
        with pytest.raises(TypeError, match="tolerence"):
            zbuf_occlude.visible_mask(mesh, points, cam, method, face_index=fi, tolerence=0.5)
    with pytest.raises(TypeError, match="resolution"):
        zbuf_occlude.visible_mask(mesh, points, cam, "oracle", face_index=fi, resolution=512)  # an image-space option
    with pytest.raises(TypeError, match="tolerence"):
        zbuf_occlude.VisibilitySession(mesh, points, fi, tolerence=0.5)
    with method_info("auto").session(mesh, points, fi) as scene, pytest.raises(TypeError, match="tolerence"):
        scene.visible(cam, tolerence=0.5)
    # the documented keywords still work and change what they should
    a = zbuf_occlude.visible_mask(mesh, points, cam, "oracle", face_index=fi, tolerance=1e-6)
    assert np.array_equal(a, zbuf_occlude.visible_mask(mesh, points, cam, "oracle", face_index=fi))


def test_occlude_object_refuses_a_misspelt_method_option():
    mesh = trimesh.creation.icosphere(subdivisions=1)
    for method in ("oracle", "embree-fast"):  # the one-shot path and the session path
        with pytest.raises(TypeError, match="tolerence"):
            list(occlude_object(mesh, [(0.0, 0.0)], key=1, draws=PoseDraws(n_points=16, samples_per_view=1), method=method, tolerence=0.1))


def test_a_users_method_with_var_keywords_receives_every_option(monkeypatch):
    from zbuf_occlude.visibility.registry import check_keywords, method_keywords

    got = {}

    def fn(mesh, points, camera, *, face_index=None, **options):
        got.update(options)
        return np.ones(len(points), dtype=bool)

    monkeypatch.setitem(registry._METHODS, "user-any", fn)
    assert method_keywords("user-any") is None
    check_keywords("user-any", {"anything": 1})
    mesh = trimesh.creation.icosphere(subdivisions=1)
    zbuffer_mask = zbuf_occlude.visible_mask(mesh, mesh.vertices[:5], zbuf_occlude.camera_on_sphere(0.0, 0.0), "user-any", anything=1)
    assert got == {"anything": 1} and zbuffer_mask.all()


def test_the_keywords_follow_the_function_a_name_is_bound_to(monkeypatch):
    from zbuf_occlude.visibility.registry import method_keywords

    assert "tolerance" in method_keywords("oracle")
    monkeypatch.setitem(registry._METHODS, "oracle", lambda mesh, points, camera, **options: None)
    assert method_keywords("oracle") is None
    monkeypatch.undo()
    assert "tolerance" in method_keywords("oracle")  # not the stand-in's, cached under the same name
