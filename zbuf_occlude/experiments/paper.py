"""The numbers and protocols of Sryamkin et al. 2023, Table 3 (what our results stand beside)."""

from __future__ import annotations

__all__ = ["TRAIN_ELEVATIONS", "TEST_ELEVATIONS", "PAPER_3A", "PAPER_3B", "PAPER_3B_TEST3", "PAPER_3B_MEAN_F1", "MODELNET8"]

#: Table 3A: poses of paper100 (Eq. 11–12) used for training (34) and testing (66), degrees.
TRAIN_ELEVATIONS = (-90.0, -70.0, -50.0, -20.0, 20.0, 50.0, 70.0, 90.0)
TEST_ELEVATIONS = (-80.0, -60.0, -40.0, -30.0, -10.0, 0.0, 10.0, 30.0, 40.0, 60.0, 80.0)
#: Table 3A, overall accuracy (%) at TEST_ELEVATIONS.
PAPER_3A = {
    "voxnet": (69.7, 71.1, 71.6, 74.4, 69.0, 50.3, 60.4, 69.3, 69.0, 68.0, 63.9),
    "pointnet": (65.6, 64.9, 74.4, 76.9, 75.5, 60.6, 75.6, 78.3, 78.2, 74.8, 68.0),
    "3dmfv": (97.6, 97.3, 98.0, 98.6, 97.6, 86.8, 97.7, 99.1, 98.5, 97.0, 97.3),
}
#: Table 3B (%): model → training set → (Test 1 complete meshes, Test 2 occluded clouds).
PAPER_3B = {
    "voxnet": {"C1": (81.0, 87.0), "C2": (82.0, 88.5), "C3": (87.5, 89.5)},
    "3dmfv": {"C1": (76.3, 95.2), "C2": (45.9, 81.3), "C3": (79.7, 95.7)},
}
#: Table 3B Test 3, 3DmFV at 1,024 points: accuracy on SUO "car" / "4wd" (%).
PAPER_3B_TEST3 = {"C1": (88.6, 66.7), "C2": (36.4, 42.9), "C3": (76.1, 81.0)}
PAPER_3B_MEAN_F1 = 79.3
#: "ModelNet8" of Table 3B.
MODELNET8 = ("airplane", "bed", "bookshelf", "bottle", "car", "chair", "lamp", "table")
