"""The version of zbuf_occlude: the one place it is written (pyproject.toml reads it from here),
and the install command of an optional extra."""

__version__ = "0.1.0"

__all__ = ["WHEEL_NAME", "install_hint", "extra_requirements"]

#: The file name of this version's wheel, as ``pip wheel . --no-deps -w dist`` builds it (pure Python).
WHEEL_NAME = f"zbuf_occlude-{__version__}-py3-none-any.whl"
#: The distribution's name, whose metadata lists each extra's packages.
DISTRIBUTION = "zbuf-occlude"


def extra_requirements(extra: str) -> list[str]:
    """The packages of an optional extra, as the installed distribution's metadata lists them
    (``["pycollada<1,>=0.8"]`` for ``collada``); a marker other than the extra's is kept
    (``triton<4,>=3; sys_platform == "linux"``).  Empty when the extra or the metadata is unknown
    (the package run from a source tree that was never installed)."""
    from importlib import metadata

    try:
        requires = metadata.requires(DISTRIBUTION) or []
    except metadata.PackageNotFoundError:
        return []
    out, clause = [], f"extra == '{extra}'"
    for req in requires:
        spec, _, marker = (part.strip() for part in req.partition(";"))
        marker = marker.replace('"', "'")
        if marker == clause:
            out.append(spec)
        elif marker.endswith(f" and {clause}"):  # another condition first, as the metadata writes it
            out.append(f"{spec}; {marker.removesuffix(f' and {clause}')}".replace("'", '"'))
    return out


def install_hint(extra: str) -> str:
    """How to install an optional extra of ``pyproject.toml`` (``[project.optional-dependencies]``),
    in a command that works from any directory.

    No package index serves zbuf-occlude, so ``pip install 'zbuf-occlude[EXTRA]'`` fails, and
    ``pip install '.[EXTRA]'`` works only inside a checkout: the hint installs the extra's own
    packages (:func:`extra_requirements`), which every index serves.

    Parameters
    ----------
    extra : str
        The extra's name (``"learn"``, ``"pyg"``, ``"collada"``, ...).

    Returns
    -------
    str
        ``pip install 'pycollada<1,>=0.8' (the collada extra)``, for a message that says what to do;
        where the installed metadata does not list the extra, the commands for a checkout and for
        this version's wheel.
    """
    packages = extra_requirements(extra)
    if packages:
        return "pip install " + " ".join(f"'{p}'" for p in packages) + f" (the {extra} extra)"
    return f"pip install '.[{extra}]' from a checkout, or pip install 'dist/{WHEEL_NAME}[{extra}]' from a built wheel"
