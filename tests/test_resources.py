"""Memory available under an address-space limit (``ulimit -v``): zbuf_occlude.resources."""

from __future__ import annotations

import textwrap

import pytest

from zbuf_occlude.errors import InsufficientMemoryError
from zbuf_occlude.resources import check_memory

#: What the child may map beyond its footprint after importing the package.
_ROOM_BYTES = 1 << 30


def _in_limited_child(body: str) -> str:
    """What ``body`` prints in a child whose address space is its footprint plus :data:`_ROOM_BYTES` (tests/memory_limit.py)."""
    from memory_limit import run_python_limited

    code = "from zbuf_occlude import resources\nfrom zbuf_occlude.errors import InsufficientMemoryError\n" + textwrap.dedent(body)
    done = run_python_limited(code, timeout=120, headroom=_ROOM_BYTES)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def test_available_memory_is_the_address_space_left_under_rlimit_as() -> None:
    out = _in_limited_child(
        """
        available, source = resources.available_memory()
        print(available <= (1 << 30), "ulimit -v" in source)
        """
    )
    assert out.split() == ["True", "True"]


def test_check_memory_refuses_what_the_address_space_limit_cannot_hold_naming_it() -> None:
    out = _in_limited_child(
        """
        try:
            resources.check_memory(2 << 30, option="--points")
        except InsufficientMemoryError as exc:
            print(exc)
        resources.check_memory(256 << 20, option="--points")  # fits: no error
        print("fits")
        """
    )
    refusal, fits = out.strip().splitlines()
    assert refusal.startswith("--points needs about") and "ulimit -v" in refusal
    assert fits == "fits"


def test_no_address_space_limit_adds_no_candidate() -> None:
    import resource

    from zbuf_occlude.resources import _address_space_room

    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    assert (_address_space_room() is None) == (soft == resource.RLIM_INFINITY)


#: Checked in a child whose address space is its footprint plus 1.5 GiB (tests/memory_limit.py):
#: 4 GiB must be refused there, naming the input; 256 MiB must pass.
_UNDER_LIMIT = """
import sys
from zbuf_occlude.errors import InsufficientMemoryError
from zbuf_occlude.resources import check_memory
check_memory(256 << 20, "a small input")
try:
    check_memory(4 << 30, "the cloud big.ply (9,900,000 points)")
except InsufficientMemoryError as exc:
    print(exc)
    sys.exit(3)
"""


def test_more_than_the_memory_available_is_refused_in_one_line_naming_the_input():
    with pytest.raises(
        InsufficientMemoryError, match=r"^the cloud big\.ply \(9 points\) needs about .* more than the .* available"
    ) as caught:
        check_memory(1 << 60, "the cloud big.ply (9 points)")  # more than any machine holds
    assert "\n" not in str(caught.value)
    check_memory(1 << 20, "a small input")


def test_the_address_space_left_under_a_limit_is_what_counts():
    from memory_limit import run_python_limited

    done = run_python_limited(_UNDER_LIMIT)
    assert done.returncode == 3 and not done.stderr, done.stdout + done.stderr
    line = done.stdout.strip()
    assert line.startswith("the cloud big.ply (9,900,000 points) needs about 4 GiB of memory") and "ulimit -v" in line and "\n" not in line
