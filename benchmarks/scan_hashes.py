"""SHA-256 of what the scan command and ``zo.scan`` write over a fixed set of settings: the check that a
refactor of the scanner changes no result.

usage: python benchmarks/scan_hashes.py [--out FILE] [--check FILE] [--only NAME,...]

Runs 13 ``zbuf-occlude scan`` commands (presets of every kind, the footprint and its casts, several
returns, return modes, transmittance, the waveform rule, airborne, crops, LAS and LAZ, the z-buffer
backend) on the shipped chair, the unit primitives and the shipped street scene, and 9 ``zo.scan`` / ``zo.scan_airborne`` calls,
each in a fresh folder.  An ``.npz`` is hashed array by array (name, dtype, shape, bytes), so a zip's
layout does not count; every other file byte for byte.  Prints one line per case, ``NAME SHA256``;
``--out`` writes them to a file, ``--check`` compares with a file written before (lines starting with
``#`` are comments) and exits 1 naming each case that differs; ``benchmarks/scan_hashes.txt`` holds the
hashes of the commit it names, on the machine it names.  Takes 1-3 minutes on 2 cores (the z-buffer case needs an OpenGL context:
llvmpipe will do).
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
CHAIR = REPO / "data" / "samples" / "chair" / "train" / "chair_0001.off"
STREET = REPO / "data" / "scenes" / "street.json"

#: name -> the scan command's arguments after the mesh ({chair}, {street}: the shipped files; --out and
#: --no-progress are added).
CLI_CASES = {
    "hdl32e": "{chair} --sensor hdl32e",
    "vlp16_crops": "{chair} --sensor vlp16 --samples 3 --distance 5:15 --azimuth=-30:30 --yaw 0:360 --crop --seed 4",
    "footprint": "{chair} --sensor hdl32e --footprint --divergence 0.3",
    "footprint_exact": "{chair} --sensor hdl32e --footprint --divergence 0.3 --max-returns 3 --range-resolution 0.3 --footprint-cast exact",
    "multi_return": "{chair} --sensor hdl64e --footprint --divergence 0.3 --max-returns 3 --range-resolution 0.3 --power-noise 0.1",
    "dual": "{chair} --sensor hdl32e --footprint --return-mode dual --range-resolution 0.3",
    "waveform": "{chair} --sensor os1-64 --footprint --max-returns 3 --range-resolution 0.3 --echo-rule waveform",
    "transmittance": "box --sensor hdl32e --max-returns 3 --range-resolution 0.3 --transmittance 0.4 --size 2",
    "airborne_las": "{chair} --sensor riegl-vq780i --size 3 --format las --crs EPSG:2154",
    "ray_table_laz": "cylinder --sensor livox-mid70 --size 2 --format laz",
    "depth_camera_scene": "{street} --sensor kinect-v1",
    "reflectivity_ply": "{chair} --sensor hdl32e --reflectivity 0.1:0.9 --samples 2 --format both --frame world",
    "zbuffer_scene": "{street} --sensor vlp16 --backend zbuffer --samples 2",
}


def _api_cases() -> dict:
    """name -> a function returning a Scan: the library's entry points without the command line."""
    import zbuf_occlude as zo
    from zbuf_occlude.sensors import RAY_TABLE_PRESETS, airborne_preset, scan_airborne, with_beam

    import trimesh

    def scene():
        box = trimesh.creation.box(extents=(2.0, 1.0, 1.5))
        return zo.ScanScene().add(str(CHAIR), class_name="chair", position_m=(8, 1), size_m=1.2).add(box, class_name="box",
                                                                                                    position_m=(12, -2))  # fmt: skip

    hdl = zo.Lidar.preset("hdl32e")
    foot = with_beam(hdl, footprint_rays=7, divergence_deg=0.3, max_returns=3, range_resolution_m=0.3)
    return {
        "api_hdl32e": lambda: zo.scan(scene(), hdl, seed=1),
        "api_world": lambda: zo.scan(scene(), zo.Lidar.preset("vlp16"), seed=2, frame="world"),
        "api_sector": lambda: zo.scan(scene(), hdl, seed=3, azimuth_range_deg=(-10.0, 20.0)),
        "api_footprint": lambda: zo.scan(scene(), foot, seed=4),
        "api_footprint_exact": lambda: zo.scan(scene(), foot, seed=4, footprint="exact"),
        "api_reflectivity": lambda: zo.scan(scene(), hdl, seed=5, reflectivity=0.3),
        "api_transmittance": lambda: zo.scan(scene(), foot, seed=6, transmittance=0.5),
        "api_ray_table": lambda: zo.scan(scene(), RAY_TABLE_PRESETS["livox-mid70"], seed=7),
        "api_airborne": lambda: scan_airborne(scene(), airborne_preset("riegl-vq780i"), seed=8),
    }


def _hash_npz(path: Path, h) -> None:
    with np.load(path, allow_pickle=False) as z:
        for name in sorted(z.files):
            a = z[name]
            h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
            h.update(np.ascontiguousarray(a).tobytes())


def hash_folder(folder: Path) -> str:
    """SHA-256 over every file below ``folder``, by relative path (``.npz`` array by array; a LAS/LAZ file without its
    header's creation date, so that a scan made on another day hashes the same)."""
    h = hashlib.sha256()
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        h.update(path.relative_to(folder).as_posix().encode() + b"\0")
        if path.suffix == ".npz":
            _hash_npz(path, h)
        elif path.suffix in (".las", ".laz"):  # the header's file creation day and year (bytes 90-93) say when, not what
            data = bytearray(path.read_bytes())
            data[90:94] = bytes(4)
            h.update(bytes(data))
        else:
            h.update(path.read_bytes())
    return h.hexdigest()


def hash_scan(s) -> str:
    """SHA-256 of a Scan's arrays (every field that is an array, by name) and its sensor's name."""
    h = hashlib.sha256(str(getattr(s, "sensor_name", "")).encode())
    for name in sorted(vars(s)):
        value = getattr(s, name)
        if isinstance(value, np.ndarray):
            h.update(f"{name}|{value.dtype.str}|{value.shape}|".encode())
            h.update(np.ascontiguousarray(value).tobytes())
    return h.hexdigest()


def run(only: set[str] | None) -> dict[str, str]:
    from zbuf_occlude.cli.main import main

    out: dict[str, str] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, argv in CLI_CASES.items():
            if only and name not in only:
                continue
            folder = Path(tmp) / name
            argv = [a.format(chair=CHAIR, street=STREET) for a in argv.split()]
            status = main(["scan", *argv, "--out", str(folder), "--no-progress"])
            out[name] = f"{hash_folder(folder)} exit={status}"
    for name, make in _api_cases().items():
        if not only or name in only:
            out[name] = hash_scan(make())
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="write the hashes to this file")
    parser.add_argument("--check", type=Path, help="compare with a file written before; exit 1 on a difference")
    parser.add_argument("--only", help="NAME,...: these cases alone")
    args = parser.parse_args()
    only = set(args.only.split(",")) if args.only else None
    got = run(only)
    lines = [f"{name} {digest}" for name, digest in got.items()]
    print("\n".join(lines))
    if args.out:
        args.out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    if args.check:
        text = args.check.read_text(encoding="utf-8").splitlines()
        before = dict(line.split(" ", 1) for line in text if line.strip() and not line.startswith("#"))
        differ = [name for name in got if before.get(name) != got[name]]
        if differ:
            print(f"differ: {', '.join(differ)}", file=sys.stderr)
            return 1
        print(f"all {len(got)} equal", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
