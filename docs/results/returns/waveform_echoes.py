"""A diagnostic: the returns experiment's plot with echoes told apart on each pulse's waveform, not on chains of hits.

    python docs/results/returns/waveform_echoes.py MESH_FOLDER REAL_LAZ RULE DIVERGENCES_MRAD K_LIST > waveform_echoes.md

``echoes.resolve_echoes`` starts a new echo where a hit lies a range resolution or more beyond the
hit before it, so a weak run of hits between two strong reflections (a crown's side wall across
the footprint) joins them into one echo, and the more sub-rays, the more such runs.  Here, in
this process only (``echo_model.resolve_echoes`` is replaced), a pulse's echoes are the peaks of
its waveform instead: the hits' energies each spread as a Gaussian in range of σ = half the range
resolution (two equal reflections one resolution apart give two peaks), peaks less than a
resolution apart kept as the stronger, every hit given to the peak of its basin (split at the
waveform's minimum between peaks), the echo's range its peak's, its energy its hits' sum (RULE
``waveform``) or the waveform's height at the peak in a narrow echo's units (RULE ``amplitude``:
a full-waveform receiver's peak amplitude), detection and the first returns as the library's.
RULE ``chain``: the library's own rule, for the same run.

The scanner and plot are ``experiment returns``'s (the IGN sample's fitted return model, the
trees spaced for the tile's tree cover, two pooled flight lines); per divergence (mrad) and K the
figures the experiment compares.  A what-if for the receiver model, not a change of it.
"""

from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

import zbuf_occlude.sensors.beam.echo_energy as echo_model
from zbuf_occlude.experiments.returns import IGN_ALTITUDE_M, simulate
from zbuf_occlude.experiments.tree_cover import tree_cover
from zbuf_occlude.experiments.returns_report import ReturnsSettings, ign_plot, simulated_model
from zbuf_occlude.io.las import read_las
from zbuf_occlude.sensors.beam.echoes import MIN_RANGE_M, Echoes, number_returns
from zbuf_occlude.sensors.fit.return_model import fit_return_model

BOOTSTRAP = 20
#: Grid step of a pulse's waveform, in σ.
STEP_SIGMA = 0.2


def _peaks(r: np.ndarray, e: np.ndarray, sigma: float, resolution: float) -> tuple[np.ndarray, list[float]]:
    """The waveform's peaks (ranges) and the cut ranges between their basins, for one pulse's sorted hits."""
    if r[-1] - r[0] <= 2.0 * sigma or len(r) == 1:  # equal Gaussians within 2σ: one peak
        return np.array([float(np.dot(r, e) / e.sum()) if e.sum() > 0 else float(r.mean())]), []
    x = np.arange(r[0] - 2.0 * sigma, r[-1] + 2.0 * sigma + STEP_SIGMA * sigma, STEP_SIGMA * sigma)
    w = (e[None, :] * np.exp(-0.5 * ((x[:, None] - r[None, :]) / sigma) ** 2)).sum(axis=1)
    kept: list[int] = []
    for q in np.flatnonzero((w[1:-1] > w[:-2]) & (w[1:-1] >= w[2:])) + 1:
        if kept and x[q] - x[kept[-1]] < resolution:  # told apart from one resolution on: the stronger
            kept[-1] = q if w[q] > w[kept[-1]] else kept[-1]
        else:
            kept.append(int(q))
    if not kept:
        return np.array([float(np.dot(r, e) / e.sum())]), []
    cuts = [float(x[a + int(np.argmin(w[a:b]))]) for a, b in zip(kept[:-1], kept[1:])]
    return x[kept], cuts


def waveform_echoes(pulse, range_m, energy, surface, *, range_resolution_m, detection_threshold, max_returns, min_echo_reflectance=0.0,
                    amplitude: bool = False) -> Echoes:  # fmt: skip
    """``resolve_echoes``'s signature and result, echoes as the waveform's peaks (module docstring)."""
    p, r, e, s = (np.asarray(v) for v in (pulse, range_m, energy, surface))
    order = np.lexsort((r, p))
    p, r, e, s = p[order].astype(np.int64), r[order].astype(float), e[order].astype(float), s[order].astype(np.int64)
    sigma = range_resolution_m / 2.0
    starts = np.flatnonzero(np.r_[True, p[1:] != p[:-1]])
    out = []
    for a, b in zip(starts, np.r_[starts[1:], len(p)]):
        peaks, cuts = _peaks(r[a:b], e[a:b], sigma, range_resolution_m)
        bounds = np.r_[0, np.searchsorted(r[a:b], cuts), b - a] + a
        for position, g0, g1 in zip(peaks, bounds[:-1], bounds[1:]):
            if g1 <= g0:
                continue
            ids, inverse = np.unique(s[g0:g1], return_inverse=True)
            dominant = ids[int(np.argmax(np.bincount(inverse.reshape(-1), weights=e[g0:g1])))]
            rows = np.flatnonzero(s[g0:g1] == dominant) + g0
            total = float(e[g0:g1].sum())
            if amplitude:
                total = float((e[a:b] * np.exp(-0.5 * ((position - r[a:b]) / sigma) ** 2)).sum())
            out.append((p[a], float(position), total, dominant, rows[np.argmax(e[rows])]))
    columns = [np.array(c) for c in zip(*out)] if out else [np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros(0, np.int64),
                                                             np.zeros(0, np.int64)]  # fmt: skip
    P, R, E, S, H = columns
    detected = E >= detection_threshold
    if min_echo_reflectance > 0:
        detected &= E * np.maximum(R, MIN_RANGE_M) ** 2 >= min_echo_reflectance
    P, R, E, S, H = (c[detected] for c in (P, R, E, S, H))
    first = np.flatnonzero(np.r_[True, P[1:] != P[:-1]]) if len(P) else np.zeros(0, np.int64)
    rank = np.arange(len(P)) - np.repeat(first, np.diff(np.r_[first, len(P)]))
    P, R, E, S, H = (c[rank < max_returns] for c in (P, R, E, S, H))
    return_number, number_of_returns = number_returns(P)
    return Echoes(pulse=P.astype(np.int64), range_m=R.astype(float), energy=E.astype(float), surface=S.astype(np.int64),
                  hit=order[H.astype(np.int64)], return_number=return_number, number_of_returns=number_of_returns)  # fmt: skip


def main(mesh_root: str, real_path: str, rule: str, divergences: str, ks: str) -> None:
    load_start, cpu_start, wall_start = os.getloadavg(), time.process_time(), time.perf_counter()
    las = read_las(real_path)
    plot = ign_plot(mesh_root, ReturnsSettings(), tree_cover=tree_cover(las, bootstrap=BOOTSTRAP).value)
    model = simulated_model(fit_return_model(las, altitude_m=IGN_ALTITUDE_M, bootstrap=BOOTSTRAP), plot[0], True)
    scene, vegetation, centre, half = plot
    if rule != "chain":
        echo_model.resolve_echoes = lambda *args, **kwargs: waveform_echoes(*args, **kwargs, amplitude=rule == "amplitude")
    print(
        "| rule | divergence (mrad) | K | vegetation points from multi-return pulses (%) | vegetation pulses with 1 / 2 / 3 / 4 returns (%) | "
        "ground points from multi-return pulses (%) | smallest / 5th percentile / median gap (m) | intensity first-of-several / single |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for d in (float(v) for v in divergences.split(",")):
        for k in (int(v) for v in ks.split(",")):
            result = simulate(scene, model.scanner(math.degrees(d * 1e-3), k), vegetation, center_xy=centre, half_size_m=half,
                              seeds=(0, 1), bootstrap=BOOTSTRAP, reflectivity=model.reflectivity)  # fmt: skip
            v, a = result.statistics["vegetation"].estimates, result.statistics["all"].estimates
            shares = " / ".join(f"{100 * v[f'returns_{n}'].value:.2f}" for n in (1, 2, 3, 4))
            print(f"| {rule} | {d:g} | {k} | {100 * a['multi_return_points_classes_3_4_5'].value:.1f} | {shares} | "
                  f"{100 * a['multi_return_points_class_2'].value:.1f} | {a['gap_min'].value:.3f} / {a['gap_p05'].value:.3f} / "
                  f"{a['gap_median'].value:.2f} | {a['intensity_ratio_classes_3_4_5'].value:.3f} |", flush=True)  # fmt: skip
    print(f"\nload average {', '.join(f'{v:.2f}' for v in load_start)} at the start, "
          f"{', '.join(f'{v:.2f}' for v in os.getloadavg())} at the end; {time.perf_counter() - wall_start:.0f} s, "
          f"{time.process_time() - cpu_start:.0f} CPU seconds")  # fmt: skip


if __name__ == "__main__":
    main(*sys.argv[1:6])
