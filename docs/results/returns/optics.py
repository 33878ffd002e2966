"""The fitted simulation with the reflectance table's values: foliage that reflects and lets light through, for docs/results/returns.md.

    python docs/results/returns/optics.py MESH_FOLDER IGN_LAZ DIVERGENCE_DEG K RESOLUTION_M > optics.md

Scans the experiment's plot as ``experiment returns`` does at the given divergence, sub-ray count
and range resolution, once as the experiment does (every surface reflects alike and stops the
sub-ray) and once with the table of zbuf_occlude.sensors.scene.materials at 1064 nm: the ground soil,
the meshes foliage (its reflectance, and its round-trip transmittance: the sub-ray goes on through
it, weakened).  Prints the vegetation figures of both beside the real file's.
"""

from __future__ import annotations

import sys

from zbuf_occlude.experiments.returns import ign_scanner, pulse_subset, simulate
from zbuf_occlude.experiments.returns_report import ReturnsSettings, ign_plot
from zbuf_occlude.io.las import read_las
from zbuf_occlude.sensors.fit.returns import return_statistics
from zbuf_occlude.sensors.scene.materials import MATERIALS, WAVELENGTHS_NM


def row(name: str, every, veg) -> str:
    shares = " / ".join(f"{100 * veg[f'returns_{n}'].value:.1f}" for n in (1, 2, 3, 4))
    return (
        f"| {name} | {shares} | {100 * every['multi_return_points_classes_3_4_5'].value:.1f} | {every['gap_median'].value:.2f} | "
        f"{every['intensity_ratio_classes_3_4_5'].value:.3f} ± {every['intensity_ratio_classes_3_4_5'].std:.3f} |"
    )


def main(argv: list[str]) -> None:
    meshes, ign, divergence, k, resolution = argv[0], argv[1], float(argv[2]), int(argv[3]), float(argv[4])
    # the 14 m spacing its recorded figures were made with (before the plot matched the tile's tree cover)
    settings = ReturnsSettings(spacing_m=14.0)
    scene, vegetation, centre, half = ign_plot(meshes, settings)
    column = WAVELENGTHS_NM.index(1064.0)
    soil, foliage = MATERIALS["soil"], MATERIALS["foliage"]
    rho = [soil.reflectance[column]] + [foliage.reflectance[column]] * len(vegetation)
    tau = [soil.transmittance] + [foliage.transmittance] * len(vegetation)
    print(f"soil ρ {rho[0]:.2f}; foliage ρ {rho[1]:.2f}, round-trip transmittance {tau[1]:.2f} (1064 nm)\n")
    print(
        "| run | vegetation pulses 1 / 2 / 3 / 4 returns (%) | vegetation points from multi-return pulses (%) | median gap (m) | intensity first-of-several / single, vegetation |"
    )
    print("|---|---|---|---|---|")
    scanner = ign_scanner(divergence, k, range_resolution_m=resolution)
    for name, optics in (
        ("opaque, ρ = 1 (the experiment)", {}),
        ("the table's ρ and foliage transmittance", {"reflectivity": rho, "transmittance": tau}),
    ):
        result = simulate(scene, scanner, vegetation, center_xy=centre, half_size_m=half, seeds=settings.seeds, bootstrap=50, **optics)
        print(row(name, result.statistics["all"].estimates, result.statistics["vegetation"].estimates))
    real = read_las(ign)
    print(
        row(
            "real (IGN sample)",
            return_statistics(real, bootstrap=50).estimates,
            return_statistics(pulse_subset(real, "vegetation"), bootstrap=50).estimates,
        )
    )


if __name__ == "__main__":
    main(sys.argv[1:])
