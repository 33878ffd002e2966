"""The paper's Table 3 as functions: 3A, accuracy against elevation, and 3B, augmentation (Sryamkin et al. 2023, §4.4).

The package: :mod:`.config` (:class:`Table3Config`, every setting of a run, checked once),
:mod:`.common` (the output files, the meshes planned and the farm run that renders them),
:mod:`.elevation` (:func:`run_elevation`, ``experiment elevation``, and :func:`combine_elevation`),
:mod:`.augmentation` (:func:`run_augmentation`, ``experiment augmentation``) and :mod:`.report`
(the tables beside the paper's numbers, and the plots).  Each run writes ``results.csv``,
``table.md``, ``run.json`` and its plots; its argparse face is :mod:`zbuf_occlude.cli.learn`.
"""

from zbuf_occlude.experiments.table3.augmentation import run_augmentation
from zbuf_occlude.experiments.table3.common import (
    AUGMENTATION_OUTPUTS,
    AUGMENTATION_SETS,
    CHECKPOINT_FILES,
    COMBINED_OUTPUTS,
    DATA_OUTPUTS,
    ELEVATION_OUTPUTS,
    plan_meshes,
)
from zbuf_occlude.experiments.table3.config import SCALES, Scale, Table3Config
from zbuf_occlude.experiments.table3.elevation import combine_elevation, run_elevation

__all__ = [
    "SCALES", "Scale", "Table3Config", "plan_meshes", "run_elevation", "run_augmentation", "combine_elevation", "CHECKPOINT_FILES",
    "AUGMENTATION_SETS", "ELEVATION_OUTPUTS", "AUGMENTATION_OUTPUTS", "COMBINED_OUTPUTS", "DATA_OUTPUTS",
]  # fmt: skip
