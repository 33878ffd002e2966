"""Image space vs object space: every HSR method side by side, against the oracle.

For every mesh × number of points × camera pose × method, :func:`compare` times one call
of :func:`~zbuf_occlude.visibility.visible_mask` (wall time per view) and scores its
answer against the reference method (``"oracle"``, exact):

``accuracy``
    Fraction of points on which the method agrees with the reference.
``false_visible_rate``, ``false_hidden_rate``
    Fraction of *all* points the method calls visible that the reference hides, and the
    reverse; ``accuracy = 1 - false_visible_rate - false_hidden_rate``.
``iou``
    Intersection over union of the two visible sets (1 when both are empty).
``chamfer``
    Symmetric Chamfer distance between the two output clouds (mean nearest-neighbour
    distance each way, averaged; object units, meshes normalised to extent 1).

Optional sweeps score the image-space methods at several z-buffer resolutions and the
occupancy grid at several grid sizes.  :func:`write_results` writes ``results.csv``, a
Markdown report and PNG plots; :func:`table_1a` and :func:`table_1b` format the
reproduction of Sryamkin et al. 2023, Table 1A/1B.  :func:`run_compare` is the whole
``zbuf-occlude compare`` command.

A method that raises on a mesh is recorded in its row's ``error`` column and in the
report, and the run goes on.

The package: :mod:`.config` (:class:`CompareConfig`, every setting of a run, checked once),
:mod:`.run` (the timed, scored run), :mod:`.results` (``results.csv`` and
summaries), :mod:`.report` (Markdown report and plots), :mod:`.tables` (the paper's
Table 1A/1B) and :mod:`.job` (:func:`run_compare`, the whole command; its argparse face is
:mod:`zbuf_occlude.cli.compare`).
"""

from zbuf_occlude.defaults import DEFAULT_VIEWS
from zbuf_occlude.experiments.compare.config import (
    DEFAULT_METHODS,
    DEFAULT_POINTS,
    DEFAULT_REFERENCE,
    CompareConfig,
    parse_int_list,
    parse_methods,
)
from zbuf_occlude.experiments.compare.job import run_compare
from zbuf_occlude.experiments.compare.report import write_results
from zbuf_occlude.experiments.compare.results import RESULT_FIELDS, read_csv, summarise, write_csv
from zbuf_occlude.experiments.compare.run import GRID_SWEEP, RESOLUTION_SWEEP, chamfer_distance, compare
from zbuf_occlude.experiments.compare.tables import PAPER_TABLE_1A_REDUCTION, PAPER_TABLE_1B_REDUCTION, table_1a, table_1b

__all__ = [
    "CompareConfig",
    "chamfer_distance",
    "parse_methods",
    "parse_int_list",
    "compare",
    "write_results",
    "write_csv",
    "read_csv",
    "summarise",
    "table_1a",
    "table_1b",
    "run_compare",
    "RESULT_FIELDS",
    "DEFAULT_METHODS",
    "DEFAULT_POINTS",
    "DEFAULT_VIEWS",
    "DEFAULT_REFERENCE",
    "RESOLUTION_SWEEP",
    "GRID_SWEEP",
    "IMAGE_SPACE_METHODS",
    "GRID_METHODS",
    "PAPER_TABLE_1A_REDUCTION",
    "PAPER_TABLE_1B_REDUCTION",
]


def __getattr__(name: str):
    # IMAGE_SPACE_METHODS and GRID_METHODS are read from the registry when first used (run.py)
    if name in ("IMAGE_SPACE_METHODS", "GRID_METHODS"):
        from zbuf_occlude.experiments.compare import run

        return getattr(run, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
