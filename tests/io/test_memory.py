"""The one memory check before the work (zbuf_occlude.io.memory): an input's size against the memory available."""

from __future__ import annotations

import pytest

from zbuf_occlude.errors import InsufficientMemoryError
from zbuf_occlude.io.memory import check_memory

#: Checked in a child whose address space is its footprint plus 1.5 GiB (tests/memory_limit.py):
#: 4 GiB must be refused there, naming the input; 256 MiB must pass.
_UNDER_LIMIT = """
import sys
from zbuf_occlude.errors import InsufficientMemoryError
from zbuf_occlude.io.memory import check_memory
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
