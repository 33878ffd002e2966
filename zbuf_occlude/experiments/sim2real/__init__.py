"""Sim-to-real: classifiers trained only on clouds made from meshes, tested on real scans (``experiment sim2real``).

The package: :mod:`.config` (:class:`Sim2RealConfig`, every setting of a run, checked once),
:mod:`.real` (the real scans as clouds and their fixed halves), :mod:`.data` (the training sets), :mod:`.outputs` (the files a run writes, ``runs.jsonl``),
:mod:`.report` (mean ± std over seeds, permutation tests, the table and the figure) and :mod:`.run`
(:func:`run_sim2real`, the whole command; its argparse face is :mod:`zbuf_occlude.cli.sim2real`).
The meshes per class and their whole-mesh splits are :mod:`zbuf_occlude.mesh.inputs.class_folders`'s, where the LiDAR
crops are placed and how each mesh is shaped :mod:`zbuf_occlude.sensors.fit.class_placement`'s (``fit-sensor --meshes``
places its crops so too).  The protocol and the results: docs/results/sim2real.md.
"""

from zbuf_occlude.experiments.sim2real.config import (
    FITTED_SHAPES,
    SIM2REAL_RECIPE,
    SIM2REAL_SCALES,
    VALIDATION_CHOICES,
    Sim2RealConfig,
    Sim2RealScale,
)
from zbuf_occlude.experiments.sim2real.outputs import ALL_SCANS, CHOSEN_ON_FIT_HALF, REAL_TO_REAL, SIM2REAL_FILES, SIM2REAL_OUTPUTS
from zbuf_occlude.experiments.sim2real.report import summarise
from zbuf_occlude.experiments.sim2real.run import Sim2RealSets, prepare_sets, run_seed, run_sim2real, write_outputs

__all__ = [
    "Sim2RealConfig", "Sim2RealScale", "SIM2REAL_SCALES", "REAL_TO_REAL", "SIM2REAL_RECIPE", "VALIDATION_CHOICES", "FITTED_SHAPES",
    "CHOSEN_ON_FIT_HALF", "ALL_SCANS", "Sim2RealSets", "run_sim2real", "prepare_sets", "run_seed", "write_outputs", "summarise",
    "SIM2REAL_FILES", "SIM2REAL_OUTPUTS",
]  # fmt: skip
