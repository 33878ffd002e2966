"""Real scans: the records of real object scans and the readers of their files.

:mod:`.records` (:class:`RealScan`, :func:`normalize_points`), :mod:`.files` (point files in
common formats: CSV/TXT/XYZ/PTS, PLY, PCD, NPY/NPZ, KITTI ``.bin``; a folder of them by class),
:mod:`.datasets` (the Sydney Urban Objects and LiDARNet layouts, :func:`load_real_scans`).
"""

from zbuf_occlude.real_scans.datasets import load_real_scans
from zbuf_occlude.real_scans.files import load_scan_folder, read_points
from zbuf_occlude.real_scans.records import RealScan, normalize_points

__all__ = ["RealScan", "normalize_points", "load_real_scans", "load_scan_folder", "read_points"]
