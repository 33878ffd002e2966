"""A families fit (zbuf_occlude/mesh/families/fitted.py): ``widen`` stretches x and y about the base's
centre and leaves the height; ``write_family(width_scale=...)`` records the range and each factor and
changes nothing else; ``read_families_fit`` refuses a damaged or hostile file in one line naming the
file and the key, never a value read from it; and ``zbuf-occlude families FAMILY --fit FILE``."""

from __future__ import annotations

import copy
import json
import math
import os
import threading
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.cli.main import main
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.caps import MAX_METADATA_BYTES
from zbuf_occlude.mesh.families import FAMILIES, write_family
from zbuf_occlude.mesh.families.fitted import (
    FAMILIES_FIT_FORMAT,
    MAX_WIDTH_SCALE,
    MIN_WIDTH_SCALE,
    ChosenFamily,
    FamiliesFit,
    read_families_fit,
    widen,
)

FEW = settings(max_examples=15, deadline=None)
#: A value placed in a fit file: no message may show it (nor a piece of it).
CANARY = "CANARY_SECRET_123"
PIECES = (CANARY, "CANARY", "SECRET_123")
POLE_FAMILIES = sorted(f for f, fam in FAMILIES.items() if fam.class_name == "pole")

GOOD = {
    "format": FAMILIES_FIT_FORMAT,
    "fitted_on": CANARY,  # what the fit saw: kept in the record, never read
    "classes": {
        "pole": {"chosen": {"trunk": {"width_scale": [0.8, 1.5], "share": 0.6}, "sign_post": {"width_scale": [1, 2], "share": 0.4}},
                 "measured": CANARY},
        "tree": {"chosen": {"tree": {"width_scale": [0.5, 0.5], "share": 1}}},
    },
}  # fmt: skip


def leaks(text: str) -> list[str]:
    return [piece for piece in PIECES if piece in text]


def write_fit(path: Path, doc: object) -> Path:
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


def assert_refused(path: Path, *words: str) -> str:
    """``read_families_fit(path)`` raises one line naming the file (and ``words``), no canary."""
    with pytest.raises(InvalidInputError) as info:
        read_families_fit(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message, message
    assert not leaks(message), message
    for word in words:
        assert word in message, (word, message)
    return message


# -- widen ---------------------------------------------------------------------------------------
def l_shape(offset: tuple[float, float, float]) -> trimesh.Trimesh:
    """Two boxes (an L, its centroid off its bounding-box centre), moved off the origin."""
    a = trimesh.creation.box(extents=[2.0, 0.5, 1.0])
    b = trimesh.creation.box(extents=[0.5, 1.5, 3.0])
    b.apply_translation([0.75, 1.0, 1.0])
    mesh = trimesh.util.concatenate([a, b])
    mesh.apply_translation(offset)
    return mesh


SCALES = st.floats(MIN_WIDTH_SCALE, MAX_WIDTH_SCALE, allow_nan=False)
OFFSETS = st.tuples(*[st.floats(-50, 50, allow_nan=False)] * 3)


@FEW
@given(a=SCALES, b=SCALES, seed=st.integers(0, 2**32 - 1), offset=OFFSETS)
def test_widen_stretches_x_and_y_about_the_base_centre_and_keeps_the_height(a: float, b: float, seed: int, offset) -> None:
    lo, hi = sorted((a, b))
    mesh = l_shape(offset)
    before = mesh.bounds.copy()
    factor = widen(mesh, np.random.default_rng(seed), (lo, hi))
    after = mesh.bounds
    assert lo <= factor <= hi
    assert factor == np.random.default_rng(seed).uniform(lo, hi)  # one draw, uniform in the range
    np.testing.assert_allclose(after[:, 2], before[:, 2], rtol=0, atol=1e-12)  # the height, and the ground
    np.testing.assert_allclose(after.mean(axis=0)[:2], before.mean(axis=0)[:2], rtol=0, atol=1e-9)  # the base's centre
    extent_before, extent_after = np.ptp(before, axis=0), np.ptp(after, axis=0)
    np.testing.assert_allclose(extent_after[:2], factor * extent_before[:2], rtol=1e-9)
    assert extent_after[2] == pytest.approx(extent_before[2], rel=1e-12)


def test_widen_with_a_single_value_range_uses_that_value() -> None:
    mesh = trimesh.creation.box(extents=[1.0, 2.0, 3.0])
    assert widen(mesh, np.random.default_rng(0), (2.5, 2.5)) == 2.5
    np.testing.assert_allclose(mesh.extents, [2.5, 5.0, 3.0], rtol=1e-12)


# -- write_family(width_scale=...) -----------------------------------------------------------------
def manifest(run) -> dict:
    return json.loads(run.manifest.read_text(encoding="utf-8"))


@pytest.mark.parametrize(("name", "scale"), [("sign_post", (0.5, 2.0)), ("shrub", (1.5, 3.0))])
def test_a_fitted_run_widens_each_object_and_changes_nothing_else(tmp_path: Path, name: str, scale) -> None:
    plain = write_family(name, tmp_path / "plain", count=3, seed=4)
    fitted = write_family(name, tmp_path / "fit", count=3, seed=4, width_scale=scale)
    again = write_family(name, tmp_path / "again", count=3, seed=4, width_scale=scale)
    assert [f.read_bytes() for f in again.files] == [f.read_bytes() for f in fitted.files]
    assert again.manifest.read_bytes() == fitted.manifest.read_bytes()
    doc, base = manifest(fitted), manifest(plain)
    assert doc["fitted_width_scale"] == list(scale)
    factors = []
    for entry, ref in zip(doc["files"], base["files"], strict=True):
        params = dict(entry["parameters"])
        factor = params.pop("width_scale")
        factors.append(factor)
        assert scale[0] <= factor <= scale[1]
        assert params == ref["parameters"]  # the object drawn as without a fit
        assert entry["extent_m"][2] == pytest.approx(ref["extent_m"][2], rel=1e-12)
        np.testing.assert_allclose(entry["extent_m"][:2], np.array(ref["extent_m"][:2]) * factor, rtol=1e-9)
        stored = trimesh.load(tmp_path / "fit" / entry["path"], force="mesh")
        np.testing.assert_allclose(stored.extents, entry["extent_m"], rtol=1e-6)
    assert len(set(factors)) == len(factors)  # drawn per object
    assert {k: v for k, v in doc.items() if k not in ("files", "fitted_width_scale")} == {k: v for k, v in base.items() if k != "files"}


def test_without_width_scale_the_run_is_the_plain_one(tmp_path: Path) -> None:
    plain = write_family("street_light", tmp_path / "a", count=2, seed=9)
    none = write_family("street_light", tmp_path / "b", count=2, seed=9, width_scale=None)
    fitted = write_family("street_light", tmp_path / "c", count=2, seed=9, width_scale=(2.0, 3.0))
    assert [f.read_bytes() for f in none.files] == [f.read_bytes() for f in plain.files]
    assert none.manifest.read_bytes() == plain.manifest.read_bytes()
    assert "fitted_width_scale" not in manifest(plain)
    assert all("width_scale" not in e["parameters"] for e in manifest(plain)["files"])
    assert all(f.read_bytes() != p.read_bytes() for f, p in zip(fitted.files, plain.files))


@pytest.mark.parametrize("scale", [(0.05, 1.0), (1.0, 11.0), (2.0, 1.0), (math.nan, 1.0), (1.0,), "wide", (True, 2.0)])
def test_write_family_refuses_a_bad_width_scale_before_writing(tmp_path: Path, scale) -> None:
    with pytest.raises(InvalidInputError, match="width_scale"):
        write_family("trunk", tmp_path / "out", count=1, seed=0, width_scale=scale)
    assert not (tmp_path / "out").exists()


# -- read_families_fit: a good file ---------------------------------------------------------------
def test_a_good_file_is_read_with_its_ranges_and_shares(tmp_path: Path) -> None:
    fit = read_families_fit(write_fit(tmp_path / "fit.json", GOOD))
    assert fit.classes == {
        "pole": {"trunk": ChosenFamily((0.8, 1.5), 0.6), "sign_post": ChosenFamily((1.0, 2.0), 0.4)},
        "tree": {"tree": ChosenFamily((0.5, 0.5), 1.0)},
    }
    assert fit.width_scale("sign_post") == (1.0, 2.0) and fit.record == GOOD


def test_the_width_of_a_family_the_fit_did_not_choose_is_refused_naming_it(tmp_path: Path) -> None:
    fit = read_families_fit(write_fit(tmp_path / "fit.json", GOOD))
    for name in ("shrub", "utility_pole"):
        with pytest.raises(InvalidInputError, match=rf"no '{name}' family") as info:
            fit.width_scale(name)
        assert "sign_post" in str(info.value) and "trunk" in str(info.value) and not leaks(str(info.value))


# -- read_families_fit: damaged and hostile files -------------------------------------------------
def changed(edit) -> dict:
    doc = copy.deepcopy(GOOD)
    edit(doc)
    return doc


def trunk(doc: dict) -> dict:
    return doc["classes"]["pole"]["chosen"]["trunk"]


def set_in(where, key: str, value):
    return lambda doc: where(doc).__setitem__(key, value)


HUGE = 10**400  # json.dumps writes it as 401 digits; json.loads reads a Python int

#: (case, the document, words its message must hold): each value that breaks it is, where it can be, the canary.
BAD_DOCS = [
    ("a list", [CANARY, GOOD], ["must be an object", "a list of 2 items"]),
    ("a string", CANARY, ["must be an object"]),
    ("wrong format", changed(set_in(lambda d: d, "format", CANARY)), ["'format' must be"]),
    ("no format", changed(lambda d: d.pop("format")), ["'format' must be"]),
    ("classes a string", changed(set_in(lambda d: d, "classes", CANARY)), ["'classes' must be an object"]),
    ("classes a list", changed(set_in(lambda d: d, "classes", [CANARY])), ["'classes' must be an object"]),
    ("no classes", changed(lambda d: d.pop("classes")), ["'classes' must be an object", "null"]),
    ("class a string", changed(set_in(lambda d: d["classes"], "pole", CANARY)), ["classes.'pole' must be an object"]),
    ("chosen empty", changed(set_in(lambda d: d["classes"]["pole"], "chosen", {})), ["classes.'pole'.chosen holds no family"]),
    ("chosen a string", changed(set_in(lambda d: d["classes"]["pole"], "chosen", CANARY)), ["'pole'.chosen must be an object"]),
    ("chosen a list", changed(set_in(lambda d: d["classes"]["pole"], "chosen", [CANARY])), ["'pole'.chosen must be an object"]),
    ("unknown family", changed(set_in(lambda d: d["classes"]["tree"]["chosen"], "pylon", {"width_scale": [CANARY, 1], "share": 1})),
     ["'pylon': no such family"]),
    ("a long unknown family", changed(set_in(lambda d: d["classes"]["tree"]["chosen"], CANARY * 300, {"share": 1})),
     ["a key of 5,100 characters: no such family"]),
    ("a long class", changed(set_in(lambda d: d["classes"], CANARY * 300, {"chosen": CANARY})),
     ["classes.a key of 5,100 characters.chosen must be an object"]),
    ("shrub under pole", changed(set_in(lambda d: d["classes"]["pole"]["chosen"], "shrub", {"width_scale": [1, 2], "share": CANARY})),
     ["chosen.'shrub': the family writes class 'bush'"]),
    ("tree under an unknown class", changed(set_in(lambda d: d["classes"], "car", {"chosen": {"tree": {"share": CANARY}}})),
     ["classes.'car'.chosen.'tree': the family writes class 'tree'"]),
    ("family a string", changed(set_in(lambda d: d["classes"]["pole"]["chosen"], "trunk", CANARY)), ["'trunk' must be an object"]),
    ("width_scale a string", changed(set_in(trunk, "width_scale", CANARY)), ["'trunk'.width_scale must be two numbers", "a string"]),
    ("width_scale strings", changed(set_in(trunk, "width_scale", [CANARY, CANARY])), ["'trunk'.width_scale must be two numbers"]),
    ("width_scale one number", changed(set_in(trunk, "width_scale", [1.0])), ["width_scale must be two numbers"]),
    ("width_scale three numbers", changed(set_in(trunk, "width_scale", [1.0, 1.5, 2.0])), ["width_scale must be two numbers"]),
    ("width_scale an object", changed(set_in(trunk, "width_scale", {"lo": 1, "hi": CANARY})), ["width_scale must be two numbers"]),
    ("width_scale NaN", changed(set_in(trunk, "width_scale", [math.nan, 1.0])), ["width_scale must be two numbers"]),
    ("width_scale infinite", changed(set_in(trunk, "width_scale", [1.0, math.inf])), ["width_scale must be two numbers"]),
    ("width_scale booleans", changed(set_in(trunk, "width_scale", [True, True])), ["width_scale must be two numbers"]),
    ("width_scale null", changed(lambda d: trunk(d).pop("width_scale")), ["width_scale must be two numbers", "null"]),
    ("width_scale too narrow", changed(set_in(trunk, "width_scale", [0.09, 1.0])), ["width_scale must hold 0.1 <= lo <= hi <= 10"]),
    ("width_scale too wide", changed(set_in(trunk, "width_scale", [1.0, 10.5])), ["width_scale must hold"]),
    ("width_scale lo > hi", changed(set_in(trunk, "width_scale", [2.0, 1.0])), ["width_scale must hold"]),
    ("width_scale a huge integer", changed(set_in(trunk, "width_scale", [1, HUGE])), ["width_scale must hold"]),
    ("share 0", changed(set_in(trunk, "share", 0)), ["'trunk'.share must be a number in (0, 1]"]),
    ("share over 1", changed(set_in(trunk, "share", 1.5)), ["'trunk'.share must be a number in (0, 1]"]),
    ("share negative", changed(set_in(trunk, "share", -0.6)), ["share must be a number"]),
    ("share NaN", changed(set_in(trunk, "share", math.nan)), ["share must be a number", "NaN"]),
    ("share a string", changed(set_in(trunk, "share", CANARY)), ["share must be a number", "a string of 17 characters"]),
    ("share a boolean", changed(set_in(trunk, "share", True)), ["share must be a number", "true"]),
    ("share a huge integer", changed(set_in(trunk, "share", HUGE)), ["share must be a number"]),
    ("no share", changed(lambda d: trunk(d).pop("share")), ["share must be a number", "null"]),
    ("shares sum under 1", changed(set_in(trunk, "share", 0.5)), ["classes.'pole'.chosen: the shares must sum to 1"]),
    ("shares sum over 1", changed(set_in(trunk, "share", 0.7)), ["the shares must sum to 1"]),
]  # fmt: skip


@pytest.mark.parametrize(("doc", "words"), [pytest.param(doc, words, id=case) for case, doc, words in BAD_DOCS])
def test_a_damaged_fit_is_refused_naming_the_file_and_the_key_never_a_value(tmp_path: Path, doc, words) -> None:
    assert_refused(write_fit(tmp_path / "fitted_families.json", doc), *words)


@pytest.mark.parametrize("text", ["{" + CANARY, '{"format": ' + CANARY + "}", CANARY, "[1, 2", "\ufeff{}", ""])
def test_text_that_is_not_json_is_refused(tmp_path: Path, text: str) -> None:
    path = tmp_path / "fit.json"
    path.write_text(text, encoding="utf-8")
    assert_refused(path, "not valid JSON")


def test_bytes_that_are_not_utf8_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "fit.json"
    path.write_bytes(b'{"format": "' + CANARY.encode() + b'\xff"}')
    assert_refused(path, "not UTF-8")


def test_a_missing_file_and_a_folder_are_refused(tmp_path: Path) -> None:
    assert_refused(tmp_path / "missing.json", "cannot read")
    (tmp_path / "folder.json").mkdir()
    assert_refused(tmp_path / "folder.json", "cannot read")


def test_a_file_over_the_cap_is_refused_unread(tmp_path: Path) -> None:
    path = tmp_path / "big.json"
    with open(path, "wb") as fh:  # sparse: the size is checked before a byte is read
        fh.truncate(MAX_METADATA_BYTES + 1)
    assert_refused(path, f"{MAX_METADATA_BYTES + 1:,} bytes")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")
def test_a_fifo_is_refused_without_waiting_for_a_writer(tmp_path: Path) -> None:
    path = tmp_path / "fit.json"
    os.mkfifo(path)
    result: list[BaseException | None] = []

    def read() -> None:
        try:
            read_families_fit(path)
            result.append(None)
        except BaseException as exc:  # noqa: BLE001 - handed to the test's thread
            result.append(exc)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(timeout=10)
    if reader.is_alive():  # it blocked on the FIFO: a writer's open and close lets it go before failing
        os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
        reader.join(timeout=10)
        pytest.fail("read_families_fit waited for a writer on a FIFO")
    (exc,) = result
    assert isinstance(exc, InvalidInputError) and str(path) in str(exc) and "FIFO" in str(exc), exc


# -- FamiliesFit.counts --------------------------------------------------------------------------
@FEW
@given(
    families=st.lists(st.sampled_from(POLE_FAMILIES), min_size=1, max_size=len(POLE_FAMILIES), unique=True),
    weights=st.lists(st.floats(0.01, 1.0), min_size=len(POLE_FAMILIES), max_size=len(POLE_FAMILIES)),
    per_class=st.integers(1, 50),
)
def test_counts_split_each_class_by_its_shares(families: list[str], weights: list[float], per_class: int) -> None:
    total = sum(weights[: len(families)])
    pole = {f: ChosenFamily((1.0, 1.0), w / total) for f, w in zip(families, weights)}
    fit = FamiliesFit({"pole": pole, "bush": {"shrub": ChosenFamily((1.0, 2.0), 1.0)}})
    counts = fit.counts(per_class)
    assert set(counts) <= {*families, "shrub"} and all(n > 0 for n in counts.values())
    assert counts["shrub"] == per_class
    assert sum(counts.get(f, 0) for f in families) == per_class
    for f in families:
        assert abs(counts.get(f, 0) - pole[f].share * per_class) < 1, (f, counts)


def test_counts_of_a_read_file(tmp_path: Path) -> None:
    fit = read_families_fit(write_fit(tmp_path / "fit.json", GOOD))
    assert fit.counts(10) == {"trunk": 6, "sign_post": 4, "tree": 10}
    assert fit.counts(1) == {"trunk": 1, "tree": 1}  # the largest remainder: 0.6 over 0.4


# -- the command -----------------------------------------------------------------------------------
def run_cli(argv: list[str], capsys) -> tuple[int, str]:
    try:
        status = main(argv)
    except SystemExit as exc:
        status = exc.code
    return status, capsys.readouterr().err


def test_the_command_draws_the_family_with_the_fits_range(tmp_path: Path, capsys) -> None:
    fit = write_fit(tmp_path / "fitted_families.json", GOOD)
    status, err = run_cli(["families", "trunk", "--fit", str(fit), "--count", "2", "--seed", "0", "--out", str(tmp_path / "out")], capsys)
    assert status == 0, err
    doc = json.loads((tmp_path / "out" / "pole" / "trunk.manifest.json").read_text(encoding="utf-8"))
    assert doc["fitted_width_scale"] == GOOD["classes"]["pole"]["chosen"]["trunk"]["width_scale"]
    assert all(0.8 <= e["parameters"]["width_scale"] <= 1.5 for e in doc["files"]) and len(doc["files"]) == 2
    library = write_family("trunk", tmp_path / "lib", count=2, seed=0, width_scale=(0.8, 1.5))
    assert [(tmp_path / "out" / f.relative_to(tmp_path / "lib")).read_bytes() for f in library.files] == [
        f.read_bytes() for f in library.files
    ]


def test_a_family_the_fit_did_not_choose_exits_2_in_one_line(tmp_path: Path, capsys) -> None:
    fit = write_fit(tmp_path / "fitted_families.json", GOOD)
    status, err = run_cli(["families", "shrub", "--fit", str(fit), "--out", str(tmp_path / "out")], capsys)
    assert status == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert "'shrub'" in err and not leaks(err)
    assert not list((tmp_path / "out").rglob("*.ply"))


@pytest.mark.parametrize("doc", [GOOD["classes"], changed(set_in(trunk, "width_scale", [CANARY, 1]))], ids=["not a fit", "bad range"])
def test_a_damaged_fit_file_exits_nonzero_in_one_line_naming_it(tmp_path: Path, capsys, doc) -> None:
    fit = write_fit(tmp_path / "fitted_families.json", doc)
    status, err = run_cli(["families", "trunk", "--fit", str(fit), "--out", str(tmp_path / "out")], capsys)
    assert status not in (0, None) and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert str(fit) in err and not leaks(err)
    assert not list((tmp_path / "out").rglob("*.ply"))
