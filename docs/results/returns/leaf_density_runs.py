"""``experiment returns`` with another leaf area density in the plot's crowns, or another crown depth for the leaves.

    python docs/results/returns/leaf_density_runs.py LEAF_AREA_DENSITY SHELL_M OUT [alone]

The experiment runs with its defaults but ``ReturnsSettings.leaf_area_density`` (m²/m³) and, in
this process only, ``PLOT_CROWN_SHELL_M`` (metres: how deep under the mesh's surface the leaves
fill the crown) and, with ``alone``, ``add_foliage(keep_surface=False)`` (the leaves without the
meshes' faces) on the IGN and Autzen samples of ``../shared/data/als_returns`` and the bush
meshes of ``../shared/data/street_objects/bush``.  One line is printed: the density, the shell,
the verdicts, the recommended K, the fitted divergences (mrad) by K, the seconds; then the
failing rows.  The outputs go to OUT.
"""

from __future__ import annotations

import functools
import sys

import zbuf_occlude.experiments.returns_report as report
import zbuf_occlude.sensors.scene.foliage as foliage
from zbuf_occlude.experiments.returns_report import ReturnsSettings, run_returns

DATA = "../shared/data"


def main(leaf_area_density: str, shell_m: str, out: str, alone: str = "") -> None:
    report.PLOT_CROWN_SHELL_M = float(shell_m)
    if alone == "alone":
        foliage.add_foliage = functools.partial(foliage.add_foliage, keep_surface=False)
    summary = run_returns(out, f"{DATA}/street_objects/bush", f"{DATA}/als_returns/ign_lidarhd_sample.laz",
                          autzen_path=f"{DATA}/als_returns/autzen_trim.laz",
                          settings=ReturnsSettings(leaf_area_density=float(leaf_area_density)), progress=False)  # fmt: skip
    fits = [(f["K"], round(f["divergence_mrad"], 3)) for f in summary["divergence_fits"]]
    print(leaf_area_density, shell_m, alone, summary["verdicts"], summary["recommended_k"], fits, round(summary["seconds"]))
    print("\n".join(row for row in summary["table"].splitlines() if "FAIL" in row))


if __name__ == "__main__":
    main(*sys.argv[1:5])
