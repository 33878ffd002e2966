"""The machine a run was made on, in one line: what every experiment's ``run.json`` records as ``machine``."""

from __future__ import annotations

import os
import platform

__all__ = ["machine_description"]


def machine_description() -> str:
    """This machine in one line: host name, processor, CPU count, torch's and Python's versions.

    Returns
    -------
    str
        E.g. ``"host x86_64, 2 CPUs, torch 2.6.0+cpu, 3.12.3"`` (``run.json``'s ``machine``).

    Raises
    ------
    ModuleNotFoundError
        torch is not installed (the ``learn`` extra); the experiments that call this train with it.
    """
    import torch  # deferred: importing the experiments must not import torch

    cpu = platform.processor() or platform.machine()
    return f"{platform.node()} {cpu}, {os.cpu_count()} CPUs, torch {torch.__version__}, {platform.python_version()}"
