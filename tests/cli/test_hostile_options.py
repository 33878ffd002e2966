"""Hostile option values: every count, seed, real number, pose list, output folder and device of
every command is refused with exit status 2, on one line naming the option and the value, while the
command line is parsed: before a mesh is read, torch is imported or anything is written into --out.

The caps are the ``MAX_*`` constants of :mod:`zbuf_occlude.defaults`; the laws (a count past its
cap is refused, one at or below it is taken) are checked with hypothesis.
"""

from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from zbuf_occlude import defaults
from zbuf_occlude.cli import options
from zbuf_occlude.cli.main import build_parser, main
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.geometry.cameras import view_schedule

REPO_ROOT = Path(__file__).resolve().parents[2]
CHAIR = REPO_ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off"
SAMPLES = REPO_ROOT / "data" / "samples"

#: Each command with what it needs besides the option under test; ``{out}`` is a fresh folder.
COMMANDS = {
    "generate": ["generate", str(CHAIR), "--out", "{out}"],
    "validate": ["validate", str(CHAIR)],
    "compare": ["compare", str(CHAIR), "--out", "{out}"],
    "elevation-profile": ["elevation-profile", str(CHAIR), "--out", "{out}/p.png"],
    "farm": ["farm", str(SAMPLES), "--out", "{out}"],
    "farm-merge": ["farm-merge", str(SAMPLES), "--out", "{out}"],
    "scan": ["scan", "box", "--out", "{out}"],
    "realism": ["realism", str(SAMPLES), str(SAMPLES), "--out", "{out}"],
    "fit-sensor": ["fit-sensor", str(SAMPLES), "--sensor", "hdl32e", "--out", "{out}/s.json"],
    "experiment elevation": ["experiment", "elevation", str(SAMPLES), "--out", "{out}"],
    "experiment augmentation": ["experiment", "augmentation", str(SAMPLES), "--out", "{out}"],
    "experiment sim2real": ["experiment", "sim2real", str(SAMPLES), "--real", str(SAMPLES), "--out", "{out}"],
    "contact-sheet": ["contact-sheet", str(SAMPLES), "--out", "{out}/sheet.png"],
    "export": ["export", str(SAMPLES), "--to", "pointnet-h5", "--out", "{out}"],
    "families": ["families", "trunk", "--out", "{out}"],
}

#: (command, counted option, its cap in zbuf_occlude.defaults or None, the lowest value taken).
COUNTS = [
    ("generate", "--points", "MAX_POINTS", 1), ("generate", "--samples-per-view", "MAX_SAMPLES", 1),
    ("generate", "--dense-points", "MAX_POINTS", 1), ("generate", "--resolution", "MAX_RESOLUTION", 1),
    ("generate", "--complete-points", "MAX_POINTS", 0), ("generate", "--class-from", None, 1),
    ("validate", "--dense-points", "MAX_POINTS", 1),
    ("validate", "--resolution", "MAX_RESOLUTION", 1),
    ("compare", "--dense-points", "MAX_POINTS", 1),
    ("compare", "--resolution", "MAX_RESOLUTION", 1), ("compare", "--sweep-points", "MAX_POINTS", 1),
    ("compare", "--resolution-sweep", "MAX_RESOLUTION", 1), ("compare", "--grid-sweep", "MAX_GRID", 1),
    ("elevation-profile", "--dense-points", "MAX_POINTS", 1), ("elevation-profile", "--azimuths", "MAX_VIEWS", 1),
    ("elevation-profile", "--resolution", "MAX_RESOLUTION", 1),
    ("farm", "--points", "MAX_POINTS", 1), ("farm", "--samples-per-view", "MAX_SAMPLES", 1),
    ("farm", "--dense-points", "MAX_POINTS", 1), ("farm", "--resolution", "MAX_RESOLUTION", 1),
    ("farm", "--workers", "MAX_WORKERS", 1), ("farm", "--dask-local", "MAX_WORKERS", 1),
    ("farm", "--per-class", None, 1), ("farm", "--class-from", None, 1),
    ("scan", "--samples", "MAX_SAMPLES", 1), ("realism", "--min-points", "MAX_POINTS", 0),
    *[(cmd, opt, cap, 1) for cmd in ("experiment elevation", "experiment augmentation", "experiment sim2real")
      for opt, cap in (("--epochs", "MAX_EPOCHS"), ("--points", "MAX_POINTS"), ("--threads", "MAX_WORKERS"))],
    ("experiment sim2real", "--per-class", "MAX_SAMPLES", 1), ("experiment sim2real", "--seeds", "MAX_REPETITIONS", 1),
    ("experiment sim2real", "--min-returns", "MAX_POINTS", 1),
    ("contact-sheet", "--per-class", None, 1), ("contact-sheet", "--poses", None, 1), ("contact-sheet", "--dpi", None, 1),
]  # fmt: skip

#: Every command with --seed.
SEEDED = ["generate", "validate", "compare", "elevation-profile", "farm", "scan", "fit-sensor", "experiment elevation",
          "experiment augmentation", "contact-sheet", "export", "families"]  # fmt: skip
#: Every command whose --out is a folder.
OUT_FOLDERS = ["generate", "compare", "farm", "farm-merge", "scan", "realism", "experiment elevation",
               "experiment augmentation", "experiment sim2real", "export", "families"]  # fmt: skip


@pytest.fixture
def nothing_runs(monkeypatch):
    """Fails the test if a mesh is loaded or an experiment starts: the options must be refused first."""
    import zbuf_occlude.mesh.load as mesh

    def refuse(*args, **kwargs):
        raise AssertionError("work started before the options were checked")

    monkeypatch.setattr(mesh, "load_mesh", refuse)
    return refuse


def refused(capsys, argv: list[str], out: Path) -> str:
    """Run ``argv`` (``{out}`` → ``out``): exit 2, one line naming the error, nothing made at ``out``."""
    code = main([a.replace("{out}", str(out)) for a in argv])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert err.startswith("zbuf-occlude: error:") and "\n" not in err and "Traceback" not in err, err
    assert not out.exists(), f"{out} was made before the options were checked"
    return err


_fresh = itertools.count()


def fresh_out(tmp_path: Path) -> Path:
    return tmp_path / f"out{next(_fresh)}"


# -- counts: the caps' law -----------------------------------------------------------------------------
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=st.sampled_from([c for c in COUNTS if c[2]]), excess=st.integers(1, 10**40))
def test_any_count_above_its_cap_is_refused_naming_option_value_and_cap(tmp_path, capsys, nothing_runs, case, excess) -> None:
    command, option, cap_name, _ = case
    value = getattr(defaults, cap_name) + excess
    err = refused(capsys, [*COMMANDS[command], option, str(value)], fresh_out(tmp_path))
    assert f"{option} must be at most" in err and str(value) in err and cap_name in err, err


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=st.sampled_from(COUNTS), below=st.integers(1, 10**12), text=st.sampled_from(["{}", "nan", "inf", "1e12", "", "2.5", "0x10"]))
def test_any_count_below_its_lowest_or_not_whole_is_refused(tmp_path, capsys, nothing_runs, case, below, text) -> None:
    command, option, _, lowest = case
    assume(not (text == "" and option.endswith("-sweep")))  # a blank sweep is no sweep
    value = text.format(lowest - below)
    err = refused(capsys, [*COMMANDS[command], f"{option}={value}"], fresh_out(tmp_path))
    assert option in err and (value in err or repr(value) in err), err


@settings(max_examples=200, deadline=None)
@given(cap_name=st.sampled_from(sorted({c[2] for c in COUNTS if c[2]})), data=st.data())
def test_a_count_from_lowest_to_its_cap_is_taken(cap_name: str, data) -> None:
    value = data.draw(st.integers(1, getattr(defaults, cap_name)))
    assert options.count(cap_name)(str(value), "--n") == value
    assert options.count_list(cap_name)(f"{value}, {value}", "--n") == [value, value]


def test_caps_are_named_integers_in_defaults() -> None:
    for name in {c[2] for c in COUNTS if c[2]} | {"MAX_LIST_VALUES", "MAX_SEED"}:
        assert name in defaults.__all__ and isinstance(getattr(defaults, name), int) and getattr(defaults, name) >= 1


def test_every_numeric_option_of_every_command_goes_through_a_checker() -> None:
    """No option parses with a bare int or float (which has no cap and takes nan): one checker per kind."""

    def walk(parser: argparse.ArgumentParser, name: str = ""):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub_name, sub in action.choices.items():
                    yield from walk(sub, f"{name} {sub_name}".strip())
            else:
                yield name, action

    actions = list(walk(build_parser()))
    bare = [(name, a.option_strings) for name, a in actions if a.type in (int, float)]
    assert bare == [("generate", ["--severity"])]  # a level 1..5 the protocol checks, not a count
    seeds = [a for _, a in actions if "--seed" in a.option_strings]
    assert len(seeds) == len(SEEDED) and all(isinstance(a, options.Checked) and a.check is options.seed for a in seeds)


# -- pose lists: counts inside --views -----------------------------------------------------------------
HUGE_VIEWS = {
    "fibonacci billion": "fibonacci:1000000000",
    "fibonacci million digits": "fibonacci:" + "9" * 10**6,
    "list of 10**7 poses": "0:0," * 10**7,
    "cap + 1 poses": ",".join(["10:20"] * (defaults.MAX_VIEWS + 1)),
}


@pytest.mark.parametrize("command", ["generate", "validate", "compare", "farm"])
@pytest.mark.parametrize("spec", sorted(HUGE_VIEWS))
def test_a_huge_pose_schedule_is_refused_at_once_without_echoing_it(tmp_path, capsys, nothing_runs, command, spec) -> None:
    t0 = time.perf_counter()
    err = refused(capsys, [*COMMANDS[command], "--views", HUGE_VIEWS[spec]], tmp_path / "out")
    assert time.perf_counter() - t0 < 10  # it ran for hours or until memory was gone
    assert "--views" in err and "MAX_VIEWS" in err and len(err) < 400, err[:500]


@settings(max_examples=50, deadline=None)
@given(n=st.integers(defaults.MAX_VIEWS + 1, 10**60))
def test_view_schedule_refuses_any_fibonacci_count_past_the_cap(n: int) -> None:
    with pytest.raises(InvalidInputError, match=f"more than the {defaults.MAX_VIEWS:,} poses"):
        view_schedule(f"fibonacci:{n}")


def test_view_schedule_takes_the_cap_itself() -> None:
    assert len(view_schedule(f"fibonacci:{defaults.MAX_VIEWS}")) == defaults.MAX_VIEWS


@pytest.mark.parametrize(
    ("command", "argv"),
    [("compare", ["--dense-points", "1," * 10**6]), ("compare", ["--grid-sweep", "8," * 10**6]),
     ("elevation-profile", ["--elevations", "0," * 10**6]),
     ("elevation-profile", ["--elevations", "0,10", "--azimuths", str(defaults.MAX_VIEWS)])],
)  # fmt: skip
def test_huge_lists_of_other_commands_are_refused(tmp_path, capsys, nothing_runs, command, argv) -> None:
    err = refused(capsys, [*COMMANDS[command], *argv], tmp_path / "out")
    assert argv[0] in err and "MAX_" in err and len(err) < 400, err[:500]


# -- seeds: one rule, 0 <= seed <= 2**63 - 1 ----------------------------------------------------------------
@pytest.mark.parametrize("command", SEEDED)
@pytest.mark.parametrize("value", ["-1", str(2**63), str(2**64), "1e3", "nan"])
def test_every_seed_is_checked_by_one_rule(tmp_path, capsys, nothing_runs, command, value) -> None:
    err = refused(capsys, [*COMMANDS[command], "--seed", value], tmp_path / "out")
    assert "--seed must be" in err and f"got {value}" in err, err


def test_the_seed_rule_takes_its_whole_range() -> None:
    assert options.seed("0", "--seed") == 0
    assert options.seed(str(2**63 - 1), "--seed") == defaults.MAX_SEED == 2**63 - 1


def test_scan_samples_minus_one_is_refused_not_an_empty_success(tmp_path, capsys) -> None:
    err = refused(capsys, ["scan", "box", "--samples", "-1", "--out", "{out}"], tmp_path / "out")
    assert "--samples must be an integer >= 1, got -1" in err


# -- real numbers --------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("command", "option", "value"),
    [("generate", "--radius", "inf"), ("generate", "--radius", "nan"), ("validate", "--radius", "-inf"),
     ("farm", "--radius", "nan"), ("farm", "--density", "nan"), ("farm", "--density", "0"),
     ("farm", "--sensor-ground-margin", "inf"), ("compare", "--method-budget", "nan"),
     ("elevation-profile", "--elevations", "nan"), ("elevation-profile", "--elevations", "0,91"),
     ("scan", "--distance", "inf"), ("scan", "--distance", "5:nan"), ("scan", "--ground-reflectivity", "nan"),
     ("scan", "--power-noise", "inf"), ("scan", "--echo-separation", "-1"), ("scan", "--ground-margin", "nan"),
     ("scan", "--height", "1e999"), ("scan", "--min-echo-reflectance", "1.5"), ("scan", "--min-echo-reflectance", "nan"),
     ("scan", "--min-echo-reflectance", "-0.1")],
)  # fmt: skip
def test_non_finite_or_out_of_range_reals_are_refused_naming_the_value(tmp_path, capsys, nothing_runs, command, option, value) -> None:
    err = refused(capsys, [*COMMANDS[command], f"{option}={value}"], tmp_path / "out")
    assert option in err and value.split(",")[-1].split(":")[-1] in err, err


# -- --out naming a file ---------------------------------------------------------------------------------
@pytest.mark.parametrize("command", OUT_FOLDERS)
@pytest.mark.parametrize("where", ["the file", "inside the file"])
def test_out_naming_a_file_is_refused_up_front_and_the_file_is_kept(tmp_path, capsys, nothing_runs, command, where) -> None:
    file = tmp_path / "taken"
    file.write_text("mine\n")
    out = file if where == "the file" else file / "sub"
    argv = [a.replace("{out}", str(out)) for a in COMMANDS[command]]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"zbuf-occlude: error: --out {out}: ") and "\n" not in err, err
    assert f"{file} is a file, not a folder" in err
    assert file.read_text() == "mine\n"


@pytest.mark.parametrize("command", ["compare", "realism"])
def test_a_default_out_that_is_a_file_is_refused_before_work(tmp_path, capsys, nothing_runs, monkeypatch, command) -> None:
    monkeypatch.chdir(tmp_path)
    default = {"compare": "compare_out", "realism": "realism"}[command]
    (tmp_path / default).write_text("mine\n")
    argv = [a for a in COMMANDS[command] if a not in ("--out", "{out}")]
    assert main(argv) == 2
    assert f"--out {default}: the output folder {default} is a file" in capsys.readouterr().err
    assert (tmp_path / default).read_text() == "mine\n"


# -- --device: checked before any work, saying what is missing ------------------------------------------------
@pytest.fixture
def torch_cuda(monkeypatch):
    """Make this torch look like a CPU build, a CUDA build without a GPU, or one with ``n`` GPUs."""
    torch = pytest.importorskip("torch")

    def pretend(cuda: str | None, gpus: int = 0) -> None:
        monkeypatch.setattr(torch.version, "cuda", cuda)
        monkeypatch.setattr(torch.version, "hip", None)
        monkeypatch.setattr(torch.cuda, "is_available", lambda: gpus > 0)
        monkeypatch.setattr(torch.cuda, "device_count", lambda: gpus)

    return pretend


@pytest.fixture
def no_experiment_runs(monkeypatch):
    from zbuf_occlude.experiments import sim2real, table3

    def refuse(*args, **kwargs):
        raise AssertionError("the experiment started before --device was checked")

    for module, name in ((table3, "run_elevation"), (table3, "run_augmentation"), (sim2real, "run_sim2real")):
        monkeypatch.setattr(module, name, refuse)


DEVICE_CASES = {
    "cpu build": (None, 0, ["CPU-only build", "pip install torch=={release} --index-url", "--device cpu"]),
    "cuda build, no gpu": ("12.6", 0, ["built with CUDA 12.6 but sees no GPU", "torch.cuda.device_count() = 0", "driver"]),
}


@pytest.mark.parametrize("command", ["experiment elevation", "experiment augmentation", "experiment sim2real"])
@pytest.mark.parametrize("case", sorted(DEVICE_CASES))
def test_device_cuda_is_checked_before_any_work_and_says_what_is_missing(
    tmp_path, capsys, torch_cuda, no_experiment_runs, nothing_runs, command, case
) -> None:
    import torch

    cuda, gpus, says = DEVICE_CASES[case]
    torch_cuda(cuda, gpus)
    err = refused(capsys, [*COMMANDS[command], "--device", "cuda"], tmp_path / "out")
    release = torch.__version__.split("+")[0]
    for part in says:
        assert part.format(release=release) in err, err
    assert ("CPU-only" in err) == (cuda is None), err  # a CUDA build is not told to install one


def test_resolve_device_names_each_missing_piece(torch_cuda, monkeypatch) -> None:
    import torch

    from zbuf_occlude.learn.training import resolve_device

    torch_cuda("12.6", 1)
    assert resolve_device("cuda") == torch.device("cuda") and resolve_device("cuda:0") == torch.device("cuda:0")
    with pytest.raises(BackendUnavailable, match=r"no GPU 3 here; torch sees 1"):
        resolve_device("cuda:3")
    monkeypatch.setattr(torch.backends.mps, "is_built", lambda: False)
    with pytest.raises(BackendUnavailable, match="built without MPS"):
        resolve_device("mps")
    monkeypatch.setattr(torch.backends.mps, "is_built", lambda: True)
    monkeypatch.setattr(torch.backends.mps, "is_available", lambda: False)
    with pytest.raises(BackendUnavailable, match="built with MPS but cannot use it here"):
        resolve_device("mps")
    with pytest.raises(InvalidInputError, match="--device must be cpu, cuda, cuda:N or mps, got 'tpu'"):
        resolve_device("tpu")
    assert resolve_device("cpu") == torch.device("cpu")
