"""``experiment returns`` (the waveform echo rule) with another least dip between two echoes' peaks.

    python docs/results/returns/prominence_runs.py PROMINENCE OUT

``sensors.waveform.PROMINENCE`` is set in this process only, then the experiment runs with its
defaults on the IGN and Autzen samples of ``../shared/data/als_returns`` and the bush meshes of
``../shared/data/street_objects/bush``; the verdicts, the recommended K and the fitted divergences
are printed, the outputs written to OUT.
"""

from __future__ import annotations

import sys

import zbuf_occlude.sensors.beam.waveform as waveform
from zbuf_occlude.experiments.returns_report import ReturnsSettings, run_returns

DATA = "../shared/data"


def main(prominence: str, out: str) -> None:
    waveform.PROMINENCE = float(prominence)
    summary = run_returns(out, f"{DATA}/street_objects/bush", f"{DATA}/als_returns/ign_lidarhd_sample.laz",
                          autzen_path=f"{DATA}/als_returns/autzen_trim.laz", settings=ReturnsSettings(echo_rule="waveform"),
                          progress=False)  # fmt: skip
    fits = [(f["K"], round(f["divergence_mrad"], 3)) for f in summary["divergence_fits"]]
    print(prominence, summary["verdicts"], summary["recommended_k"], fits, round(summary["seconds"]))


if __name__ == "__main__":
    main(*sys.argv[1:3])
