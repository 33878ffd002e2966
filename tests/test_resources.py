"""Memory available under an address-space limit (``ulimit -v``): zbuf_occlude.resources."""

from __future__ import annotations

import subprocess
import sys
import textwrap

#: What the child may map beyond its footprint after importing the package.
_ROOM_BYTES = 1 << 30


def _in_limited_child(body: str) -> str:
    code = textwrap.dedent(
        f"""
        import resource
        from zbuf_occlude import resources
        from zbuf_occlude.errors import InsufficientMemoryError
        size = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmSize:")) * 1024
        resource.setrlimit(resource.RLIMIT_AS, (size + {_ROOM_BYTES}, resource.RLIM_INFINITY))
        """
    ) + textwrap.dedent(body)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False)
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
