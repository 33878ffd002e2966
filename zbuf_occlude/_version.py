"""The version of zbuf_occlude: the one place it is written (pyproject.toml reads it from here),
and the install command of an optional extra, which names the wheel of this version."""

__version__ = "0.1.0"

__all__ = ["WHEEL_NAME", "install_hint"]

#: The file name of this version's wheel, as ``pip wheel . --no-deps -w dist`` builds it (pure Python).
WHEEL_NAME = f"zbuf_occlude-{__version__}-py3-none-any.whl"


def install_hint(extra: str) -> str:
    """How to install an optional extra of ``pyproject.toml`` (``[project.optional-dependencies]``).

    No package index serves zbuf-occlude, so ``pip install 'zbuf-occlude[EXTRA]'`` fails: the
    extra is installed from a checkout of the repository, or from a wheel built there.

    Parameters
    ----------
    extra : str
        The extra's name (``"learn"``, ``"pyg"``, ``"collada"``, ...).

    Returns
    -------
    str
        ``pip install '.[EXTRA]' from a checkout, or pip install 'dist/WHEEL[EXTRA]' from a built wheel``,
        for a message that says what to do.
    """
    return f"pip install '.[{extra}]' from a checkout, or pip install 'dist/{WHEEL_NAME}[{extra}]' from a built wheel"
