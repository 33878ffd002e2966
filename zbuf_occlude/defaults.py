"""The defaults of zbuf_occlude, each explained once; every module and command takes them from here.

This module imports nothing from zbuf_occlude, so any layer may use it.
"""

from __future__ import annotations

__all__ = [
    "DEFAULT_METHOD",
    "DEFAULT_RESOLUTION",
    "DEFAULT_VIEWS",
    "DEFAULT_FARM_VIEWS",
    "DEFAULT_FARM_RESOLUTION",
    "DEFAULT_FARM_DENSE_POINTS",
    "DEFAULT_N_POINTS",
    "DEFAULT_SAMPLES_PER_VIEW",
    "DEFAULT_OCCLUDE_SAMPLES_PER_VIEW",
    "DEFAULT_DENSE_POINTS",
    "DEFAULT_SEED",
    "DEFAULT_SELF_HIT_TOLERANCE",
    "DEFAULT_GPU_TOLERANCE",
    "DEFAULT_DEPTH_TOLERANCE",
    "DEFAULT_SLOPE_SCALE",
    "DEFAULT_MAX_SLOPE",
    "DEFAULT_POINT_NEIGHBOURS",
    "DEFAULT_SPLAT_SCALE",
    "DEFAULT_SPLAT_TOLERANCE",
    "DEFAULT_CREASE_COS",
    "SPLAT_PIXELS_PER_RADIUS",
    "HULL_RADIUS_FACTOR_PER_POINT",
    "HULL_VETO_MAX_POINTS",
    "MAX_SPLAT_PIXELS",
    "MAX_POINT_SET_POINTS",
    "MAX_VIEWS",
    "MAX_POINTS",
    "MAX_SAMPLES",
    "MAX_RESOLUTION",
    "MAX_GRID",
    "MAX_LIST_VALUES",
    "MAX_WORKERS",
    "MAX_EPOCHS",
    "MAX_REPETITIONS",
    "MAX_SEED",
]

#: The visibility method used when none is named: ``auto`` picks, per machine, the exact
#: GPU method (``zbuffer-exact``) on a hardware renderer or the threaded Embree method
#: (``embree-fast``) on a software one (:mod:`zbuf_occlude.visibility.auto`, issue 11).
DEFAULT_METHOD = "auto"

#: Image size of cameras and z-buffers, pixels (square), for the API, ``generate``,
#: ``validate``, ``compare`` and ``elevation-profile`` (the farm has its own, smaller
#: default for throughput: :data:`DEFAULT_FARM_RESOLUTION`).
DEFAULT_RESOLUTION = 1024

#: Poses of ``generate``, ``validate``, ``compare`` and :func:`zbuf_occlude.pipeline`: the 5×5
#: grid of :func:`zbuf_occlude.geometry.cameras.view_schedule` (the farm renders the paper's 100 poses,
#: :data:`DEFAULT_FARM_VIEWS`).
DEFAULT_VIEWS = "grid25"

#: Poses of ``farm``: the paper's 100 (Sryamkin et al. 2023, §4.3, Eq. 11–12), the shape of its
#: data set (200 objects × 100 poses × 10 samples).
DEFAULT_FARM_VIEWS = "paper100"

#: Z-buffer image size of ``farm``, pixels.  512² keeps a pixel's footprint (~2.3e-3 of the
#: object's size at the default radius) far below the dense cloud's mean spacing (~5e-3 at
#: 32768 points on a unit box), so the candidate window is not the bottleneck of accuracy.
DEFAULT_FARM_RESOLUTION = 512

#: Dense cloud per object of ``farm`` (points on the whole surface, sampled once, paper §3.4).
#: 32768 leaves several thousand visible points per pose on ModelNet objects (25–45 % visible),
#: so a 2048-point sample is a proper subsample, and keeps compact storage above 1,000
#: samples/MB (12 bytes per point once + one bit per point and pose).
DEFAULT_FARM_DENSE_POINTS = 32_768

#: Points per occluded sample, the paper's (and PointNet's) 2048 (Sryamkin et al. 2023, §4.3);
#: ``generate``, the farm and :func:`zbuf_occlude.pipeline.occlude_poses`.
DEFAULT_N_POINTS = 2048

#: Samples drawn per pose from its visible points (paper §4.3): ``generate``, the farm and
#: :func:`zbuf_occlude.pipeline.occlude_poses`.
DEFAULT_SAMPLES_PER_VIEW = 10

#: Samples per pose of :func:`zbuf_occlude.occlude`, which returns one cloud per sample: one
#: cloud per pose unless asked for more.
DEFAULT_OCCLUDE_SAMPLES_PER_VIEW = 1

#: Dense cloud per object, points on the whole surface before HSR: ``generate``,
#: :func:`zbuf_occlude.pipeline.occlude_poses` and the points ``validate`` scores per mesh (the farm
#: uses fewer for throughput: :data:`DEFAULT_FARM_DENSE_POINTS`).
DEFAULT_DENSE_POINTS = 100_000

#: Global seed of every command and of the API's random draws; with the same seed and options
#: the samples are the same bytes (zbuf_occlude.geometry.samples.derive_rng).
DEFAULT_SEED = 0

#: Distance from a point, object units, within which a face meeting the point→camera
#: segment does not count as an occluder (the exact, float64 methods).  It absorbs the
#: point's own surface (coplanar duplicate faces, edges shared with neighbours) and float
#: rounding; 1e-6 of the object's maximum extent is far below any feature ModelNet or
#: ShapeNet models have.
DEFAULT_SELF_HIT_TOLERANCE = 1e-6

#: Farthest camera, object units, at which that tolerance is still decided.  Every method
#: works on the sightline ``eye - p``, whose coordinates float64 rounds by up to eps · R
#: (eps = 2**-52, R the camera's distance); that rounding is kept 2**12 times below the
#: tolerance, the headroom the float32 stages (Embree, the GPU) need on top of the float64
#: re-decisions: R <= 1e-6 / (2**-52 · 2**12) ≈ 1.1e6.  Measured on an icosphere against
#: ``oracle-numpy``: every method agrees up to R = 1.1e6; at 1e7 and 1e8 the float32
#: ``zbuffer`` disagrees on 16 % of the points (the float64 methods still agree there).
MAX_CAMERA_RADIUS = DEFAULT_SELF_HIT_TOLERANCE / (2.0**-52 * 2.0**12)

#: The same for the segment tests run in float32 on the GPU (``zbuffer``), object units:
#: float32 rounding of points and vertices is ~3e-8 per coordinate of a unit-size object,
#: magnified up to ~100× at grazing incidence.
DEFAULT_GPU_TOLERANCE = 1e-5

#: ``zbuffer-tolerance``: visible iff the point's linear depth is at most the pixel's depth
#: plus ``DEFAULT_DEPTH_TOLERANCE + DEFAULT_SLOPE_SCALE · pixel_footprint · min(tan θ,
#: DEFAULT_MAX_SLOPE)`` (object units; θ between the sightline and the point's face normal),
#: the slope-scaled bias of shadow mapping (OpenGL's ``glPolygonOffset``).  Chosen by a grid
#: search on three shipped meshes × 10 poses at 1024² (mean agreement 95.6 %, the best
#: constant-only tolerance 94.9 %); a larger slope term exposes the far side of thin parts.
DEFAULT_DEPTH_TOLERANCE = 1e-3
#: Slope term of ``zbuffer-tolerance``, in pixel footprints (see above).
DEFAULT_SLOPE_SCALE = 1.0
#: Clamp of tan θ near grazing incidence in ``zbuffer-tolerance`` (see above); README's
#: ``min(tan θ, 4)``.
DEFAULT_MAX_SLOPE = 4.0


# -- visibility of bare point clouds (``visible_mask_points``, method ``point-splat``) ---------------
# Chosen by a grid search against the exact mesh oracle on 18 ModelNet meshes that are not shipped
# (16 poses, 2,048 and 10,000 points; docs/results/point_visibility.md), never on the meshes the
# results page reports.
#: Each point's spacing is the distance to its k-th nearest neighbour: k = 4 (k = 6 is within
#: 0.3 points of it; larger k give larger splats that hide the points just beyond every edge).
DEFAULT_POINT_NEIGHBOURS = 4
#: Splat (surfel) radius, in spacings: 1.0 (0.8 leaves holes that show hidden points, up to -1.7
#: points of accuracy at 2,048 points; 1.25 hides points beyond edges, -0.4 to -1.3 points).
DEFAULT_SPLAT_SCALE = 1.0
#: A point is on the winning surfel's sheet within this distance of its tangent plane, in
#: spacings (plus the curvature allowance): 0.05 (with normals 0.02 is 0.4 points better and 0.1
#: 0.6 worse, without normals 0.1 is 0.3 better; 0 loses 8 to 12 points everywhere).
DEFAULT_SPLAT_TOLERANCE = 0.05
#: Normals within this |cos| (30°) are one smooth sheet; across a sharper crease no curvature
#: allowance is made.
DEFAULT_CREASE_COS = 0.87
#: A view of splats hands the points it sees to hidden point removal's hull test (Katz et al. 2007,
#: :func:`~zbuf_occlude.visibility.point_hull.hull_veto`) with a flipping radius of this many times the
#: farthest visible point's distance per point of the cloud: 0.5 (1,024 at 2,048 points, 5,000 at
#: 10,000).  The best single factor on the tuning meshes was 300-2,000 at 2,048 points, 3,000-10,000
#: at 10,000 and 50,000 at 100,000: it grows with the sampling density, which a cloud of one shape
#: has in proportion to its points.
HULL_RADIUS_FACTOR_PER_POINT = 0.5
#: Clouds of up to this many points get the hull test: 20,000.  It gains 0.009 of accuracy at 2,048
#: points and 0.004 at 10,000 on the tuning meshes, for one to three views' time; at 100,000 it gains
#: 0.001 for three views' time.
HULL_VETO_MAX_POINTS = 20_000
#: Splat pixels across the median splat radius: 3 (the image is sized from the splats, not set).
SPLAT_PIXELS_PER_RADIUS = 3.0
#: Most pixels of one splat image (two 4-byte buffers and one 8-byte: 64 MB); a larger image
#: gets coarser pixels.
MAX_SPLAT_PIXELS = 4_000_000
#: Points one cloud of a point-set file may hold (:func:`zbuf_occlude.io.point_sets.read_point_sets`'s
#: ``max_points``): 10⁶, which ``generate`` occludes from its 25 default poses in about 40 s on two
#: cores and 1 GiB of address space (measured; the law: :func:`zbuf_occlude.io.point_sets.occlusion_cost`),
#: far above PointNet's 2,048; a 10⁷-point cloud would need 6 GiB and 6 minutes.
MAX_POINT_SET_POINTS = 1_000_000

# -- caps of the counted options --------------------------------------------------------------------
# The largest value each counted option of the command line takes (zbuf_occlude.cli.options checks
# them while parsing, before a mesh is read or anything is written): far above any real run, they
# stop a typo or a hostile value from running until memory or time is gone.  Memory is estimated
# again per run (zbuf_occlude.resources), and --resolution against the GL's maximum where it renders.

#: Poses of one schedule (``--views fibonacci:N`` or ``EL:AZ,...``, ``--azimuths``,
#: ``--elevations``): 1,000× the paper's 100; each pose is one render per object.
MAX_VIEWS = 100_000
#: Points of one cloud (``--points``, ``--dense-points``, ``--complete-points``, ...): 10⁸ points
#: are 2.4 GB in float64, more than one object needs at any density used in the field.
MAX_POINTS = 100_000_000
#: Samples, scans or clouds drawn per pose, object or class (``--samples-per-view``,
#: ``scan --samples``, ``--per-class``): 10,000× the paper's 10 per pose; each is written.
MAX_SAMPLES = 100_000
#: Procedural objects one ``families`` run writes (``--count``): the largest family's file is under
#: 200 kB, so 2 GB at most.
MAX_FAMILY_MESHES = 10_000
#: Image size, pixels per side (``--resolution``, ``--resolution-sweep``): twice the largest
#: ``GL_MAX_TEXTURE_SIZE`` of current GPUs (32,768); one such float32 image is 16 GiB.
MAX_RESOLUTION = 65_536
#: Occupancy-grid cells per axis (``compare --grid-sweep``): 128× the paper's 32; one exact
#: test runs per occupied cell.
MAX_GRID = 4_096
#: Values in one comma-separated list of counts (``compare --dense-points`` and its sweeps):
#: each value is a whole run over every mesh and pose.
MAX_LIST_VALUES = 1_000
#: Processes or threads on one machine (``--workers``, ``--dask-local``, ``--threads``): more
#: than any machine's cores; more machines take ``--shard`` or ``--scheduler``.
MAX_WORKERS = 1_024
#: Training epochs (``--epochs``): 100× the paper's 100.
MAX_EPOCHS = 10_000
#: Repetitions of an experiment (``sim2real --seeds``), each a whole training run per training set.
MAX_REPETITIONS = 1_000
#: Largest ``--seed``: numpy takes seeds of any size, the storage does not (past 2**64 - 1 HDF5 has
#: no integer type and every object of a farm fails); int64 is the type every reader shares.
MAX_SEED = 2**63 - 1
