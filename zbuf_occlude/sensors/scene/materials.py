"""Diffuse reflectance of common materials at LiDAR wavelengths, and each scene object's from it.

A small table, :data:`MATERIALS`: the Lambertian reflectance ρ of a material at 905 nm
(spinning automotive LiDARs), 1064 nm (Nd:YAG airborne scanners) and 1550 nm (fibre-laser
scanners), its round-trip transmittance (the share of a pulse that goes on through the surface
and comes back through it: :func:`~zbuf_occlude.sensors.beam.echoes.attenuate_along_subray`), and
the source of each value.  **The values are approximate**: typical figures for a material
class, read from the sources below (a table of typical reflectances, or the level of a
library's spectra of that class at the wavelength), not averages computed from the libraries'
files; one real surface may differ by a factor of two (a white or a black car, wet or dry soil).
They give the *relative* brightness of surfaces, which is what the returns and their detection
depend on; fit the intensity scale to real scans for absolute values.

Sources (short names used in :attr:`Material.source`):

* **WL99**: A. Wehr, U. Lohr (1999), "Airborne laser scanning — an introduction and overview",
  ISPRS J. Photogramm. Remote Sens. 54(2–3), 68–82, Table 2: typical reflectivity of materials
  at 0.9 µm (deciduous trees typ. 60 %, coniferous trees typ. 30 %, smooth concrete 24 %,
  asphalt with pebbles 17 %, beach sand typ. 50 %, rough clean wood 25 %).
* **ECOSTRESS**: S. K. Meerdink, S. J. Hook, D. A. Roberts, E. A. Abbott (2019), "The
  ECOSTRESS spectral library version 1.0", Remote Sens. Environ. 230, 111196: green leaves,
  grasses and bark (non-photosynthetic vegetation); leaves and grass drop at 1550 nm where
  their water absorbs.
* **ASTER**: A. M. Baldridge, S. J. Hook, C. I. Grove, G. Rivera (2009), "The ASTER spectral
  library version 2.0", Remote Sens. Environ. 113(4), 711–715: soils, construction concrete
  and asphalt, galvanised steel and aluminium.
* **NIST skin**: C. C. Cooksey, D. W. Allen, B. K. Tsai (2017), "Reference data set of human
  skin reflectance", J. Res. NIST 122, 26: skin is bright below 1.1 µm, dark at 1550 nm (water).
* **Fresnel**: clear glass (n ≈ 1.5) reflects 4 % at each face at normal incidence; one pass
  through a pane transmits ≈ 0.92, so the round trip ≈ 0.85.
* **assumption**: no tabulated value; the figure and its reason are in the entry.

Foliage transmittance is a **gap fraction, an assumption**: a crown mesh (a closed envelope or
clumps of leaf cards) stands for a layer of leaves with gaps smaller than a sub-ray's share of the
footprint, and :data:`FOLIAGE_GAP_FRACTION` of each sub-ray's energy goes on through it (a leaf
itself scatters what it transmits, so the pulse goes on only through the gaps).  Measured crown
porosities span ~0.1–0.5; fit it to real scans' returns per pulse where you have them.

The scene's faces get their material from, in this order: the material the file gives that face
(an OBJ's ``usemtl``, a glTF primitive's material: ``mesh.metadata[FACE_MATERIALS]``, kept per
face by the loader, :func:`~zbuf_occlude.mesh.scene.face_materials`), where its name names one of
the table ("Glass_window", "leaves"); else its object's: the mesh's material name
(``mesh.visual.material.name``, where the file gave one), the object's class name
(:data:`CLASS_MATERIALS`), the mesh's name (its file's), then :data:`DEFAULT_MATERIAL`
(:func:`material_of`, :func:`scene_optics`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.scene import face_materials_of

if TYPE_CHECKING:
    from zbuf_occlude.sensors.scene.objects import BuiltScene

__all__ = [
    "AIRBORNE_WAVELENGTH_NM",
    "CLASS_MATERIALS",
    "CROWN_MATERIALS",
    "DEFAULT_MATERIAL",
    "FOLIAGE_GAP_FRACTION",
    "GROUND_MATERIAL",
    "MATERIALS",
    "SPINNING_WAVELENGTH_NM",
    "WAVELENGTHS_NM",
    "Material",
    "SceneOptics",
    "material_named",
    "material_of",
    "on_crown",
    "per_class",
    "reflectance",
    "scene_optics",
]

#: The wavelengths of the table's columns, nm.
WAVELENGTHS_NM = (905.0, 1064.0, 1550.0)
#: A wavelength is given the nearest column within this many nm (an 865 nm Ouster: the 905 nm
#: column); farther from every column the table has no value.
WAVELENGTH_TOLERANCE_NM = 100.0
#: Wavelength of the spinning LiDAR presets, nm (Velodyne 903–905 nm; Ouster's 865 nm is the same column).
SPINNING_WAVELENGTH_NM = 905.0
#: Wavelength of airborne scanners, nm (Nd:YAG 1064 nm: Riegl VQ-1560, Leica ALS; Baltsavias 1999, Table 1).
AIRBORNE_WAVELENGTH_NM = 1064.0
#: Round-trip transmittance of a foliage surface: its gap fraction (module docstring; an assumption).
FOLIAGE_GAP_FRACTION = 0.3
#: The materials of crown surfaces: a mesh that stands for leaves or needles with gaps between them
#: (the rows with :data:`FOLIAGE_GAP_FRACTION`), where :attr:`Beam.foliage_dropout
#: <zbuf_occlude.sensors.beam.fields.Beam.foliage_dropout>` loses returns.  A grown leaf is not one: it is one leaf.
CROWN_MATERIALS = ("foliage", "needles")


@dataclass(frozen=True)
class Material:
    """One row of :data:`MATERIALS`.

    Attributes
    ----------
    reflectance : (3,) float
        Lambertian reflectance ρ in [0, 1] at :data:`WAVELENGTHS_NM` (905, 1064, 1550 nm).
    transmittance : float
        Round-trip transmittance in [0, 1]; 0: opaque.
    source : str
        Where the values come from (module docstring's short names).
    """

    reflectance: tuple[float, float, float]
    transmittance: float
    source: str


#: Leaves' reflectance at :data:`WAVELENGTHS_NM`: a crown's (``"foliage"``, with its gaps) and a grown leaf's (``"grown_leaf"``, opaque).
_LEAF_REFLECTANCE = (0.60, 0.55, 0.30)

#: The table (module docstring): material name → :class:`Material`.
MATERIALS: dict[str, Material] = {
    "foliage": Material(_LEAF_REFLECTANCE, FOLIAGE_GAP_FRACTION, "WL99 deciduous trees (905); ECOSTRESS green leaves (1064, 1550); gap fraction: assumption"),
    "needles": Material((0.30, 0.30, 0.15), FOLIAGE_GAP_FRACTION, "WL99 coniferous trees (905); ECOSTRESS conifer needles (1064, 1550); gap fraction: assumption"),
    "grass": Material((0.50, 0.50, 0.30), 0.0, "ECOSTRESS green grasses"),
    "bark": Material((0.30, 0.35, 0.40), 0.0, "ECOSTRESS bark (non-photosynthetic vegetation); WL99 rough clean wood 25 %"),
    "soil": Material((0.30, 0.33, 0.40), 0.0, "ASTER soils (dry brown loams)"),
    "sand": Material((0.50, 0.50, 0.50), 0.0, "WL99 beach sand (905); ASTER sands"),
    "asphalt": Material((0.17, 0.17, 0.15), 0.0, "WL99 asphalt with pebbles (905); ASTER construction asphalt"),
    "concrete": Material((0.24, 0.30, 0.33), 0.0, "WL99 smooth concrete (905); ASTER construction concrete"),
    "metal": Material((0.45, 0.45, 0.45), 0.0, "ASTER galvanised steel and aluminium, diffuse part (a clean metal is mostly specular)"),
    "car_paint": Material((0.30, 0.30, 0.25), 0.0, "assumption: the middle of car paints, ~0.05 (black) to ~0.8 (white) in the near infrared"),
    "glass": Material((0.05, 0.05, 0.05), 0.85, "Fresnel (4 % per face, n 1.5): diffuse ρ an assumption, round trip 0.92²"),
    "skin": Material((0.55, 0.50, 0.05), 0.0, "NIST skin"),
    "clothing": Material((0.50, 0.50, 0.45), 0.0, "assumption: textile dyes are mostly transparent in the near infrared, so light and dark clothes alike reflect ~0.4-0.6"),
    "grown_leaf": Material(_LEAF_REFLECTANCE, 0.0, "foliage's reflectance, opaque: one leaf that sensors.foliage grows in a crown, whose gaps are the space between leaves"),
}  # fmt: skip

#: Material of an object whose names match nothing: concrete, a mid-grey man-made surface.
DEFAULT_MATERIAL = "concrete"
#: Material of the ground plane (object id 0): asphalt, a street.
GROUND_MATERIAL = "asphalt"

#: Words of class, material and mesh names → material (a name's word matches a key equal to
#: it, or, for keys of 4 letters or more, starting with it: "leafy", "metallic").
CLASS_MATERIALS: dict[str, str] = {
    **dict.fromkeys(("needle", "needles", "pine", "conifer", "spruce"), "needles"),
    **dict.fromkeys(("leaf", "leaves", "foliage", "canopy", "crown", "bush", "shrub", "hedge", "tree", "plant", "vegetation"), "foliage"),
    **dict.fromkeys(("bark", "trunk", "branch", "wood"), "bark"),
    **dict.fromkeys(("glass", "window", "windshield", "windscreen"), "glass"),
    **dict.fromkeys(("metal", "steel", "alumin", "chrome", "iron", "pole", "sign", "lamp", "post"), "metal"),
    **dict.fromkeys(("paint", "car", "vehicle", "truck", "bus", "van"), "car_paint"),
    **dict.fromkeys(("skin",), "skin"),
    **dict.fromkeys(("cloth", "fabric", "textile", "cotton", "pedestrian", "person", "human", "cyclist"), "clothing"),
    **dict.fromkeys(("asphalt", "road", "tarmac", "ground"), "asphalt"),
    **dict.fromkeys(("concrete", "cement", "sidewalk", "pavement", "building", "wall"), "concrete"),
    **dict.fromkeys(("grass", "lawn", "turf", "terrain"), "grass"),
    **dict.fromkeys(("soil", "dirt", "earth", "mud"), "soil"),
    **dict.fromkeys(("sand",), "sand"),
}

#: Most characters of a name looked up (a name is a label, not a text).
_MAX_NAME_CHARS = 256


def _words(name: str) -> list[str]:
    """Lower-case words of ``name``: split at anything but letters and at camel case ("LeafGreen_2" → leaf, green)."""
    return [w.lower() for w in re.findall(r"[A-Z]?[a-z]+|[A-Z]+(?![a-z])", name[:_MAX_NAME_CHARS])]


def material_named(name: str | None) -> str | None:
    """The material (a key of :data:`MATERIALS`) a class, material or mesh name names, or None.

    The first word of ``name`` that matches a key of :data:`CLASS_MATERIALS` decides ("Tree_pine":
    foliage; "pine_tree": needles); a material name itself ("car_paint") is its own.
    """
    if not name:
        return None
    if name.lower() in MATERIALS:
        return name.lower()
    for word in _words(str(name)):
        for key, material in CLASS_MATERIALS.items():
            if word == key or (len(key) >= 4 and word.startswith(key)):
                return material
    return None


def material_of(mesh=None, class_name: str = "") -> str:
    """The material of one object: its mesh's material name, else its class, else its mesh's name, else :data:`DEFAULT_MATERIAL`.

    Parameters
    ----------
    mesh : trimesh.Trimesh, optional
        ``mesh.visual.material.name`` (a file's material) and ``mesh.metadata["name"]`` (its file's name) are looked up.
    class_name : str
        The object's class (:data:`CLASS_MATERIALS`).
    """
    material = getattr(getattr(getattr(mesh, "visual", None), "material", None), "name", None)
    mesh_name = (getattr(mesh, "metadata", None) or {}).get("name")
    for name in (material, class_name, mesh_name):
        found = material_named(name if isinstance(name, str) else None)
        if found:
            return found
    return DEFAULT_MATERIAL


def _column(wavelength_nm: float) -> int:
    """Index of the :data:`WAVELENGTHS_NM` column nearest ``wavelength_nm`` (within :data:`WAVELENGTH_TOLERANCE_NM`)."""
    try:
        w = float(wavelength_nm)
    except (TypeError, ValueError):
        w = math.nan
    gaps = [abs(w - c) for c in WAVELENGTHS_NM]
    if not math.isfinite(w) or min(gaps) > WAVELENGTH_TOLERANCE_NM:
        raise InvalidInputError(
            f"wavelength_nm must lie within {WAVELENGTH_TOLERANCE_NM:g} nm of one of the table's {', '.join(f'{c:g}' for c in WAVELENGTHS_NM)} nm, "
            f"got {wavelength_nm!r}"
        )
    return int(np.argmin(gaps))


def reflectance(material: str, wavelength_nm: float = SPINNING_WAVELENGTH_NM) -> float:
    """ρ of ``material`` (a key of :data:`MATERIALS`, or a name :func:`material_named` knows) at the nearest column of ``wavelength_nm``.

    Raises
    ------
    InvalidInputError
        An unknown material (naming it and the known ones), a wavelength far from every column.
    """
    key = material_named(material)
    if key is None:
        raise InvalidInputError(f"unknown material {material!r}; the table holds {', '.join(MATERIALS)}")
    return MATERIALS[key].reflectance[_column(wavelength_nm)]


@dataclass(frozen=True)
class SceneOptics:
    """Per object id of a scene (index 0: the ground), what :func:`~zbuf_occlude.sensors.scan.scan` takes.

    Attributes
    ----------
    reflectivity : (n_objects + 1,) float64
        Lambertian ρ at the wavelength (``scan(reflectivity=...)``).
    transmittance : (n_objects + 1,) float64
        Round-trip transmittance (``scan(transmittance=...)``).
    material : tuple of str
        Each object id's material.
    wavelength_nm : float
        The table column used, nm.
    face_material : (F,) int32
        Each face of the built scene's mesh: its material's row in :data:`MATERIALS` (its file's
        material where it names one of the table, else its object's: module docstring).
    face_reflectivity, face_transmittance : (F,) float64
        ρ and round-trip transmittance of each face of the built scene's mesh, from ``face_material``;
        what the scan weighs its hits by.
    """

    reflectivity: NDArray[np.float64]
    transmittance: NDArray[np.float64]
    material: tuple[str, ...]
    wavelength_nm: float
    face_material: NDArray[np.int32]
    face_reflectivity: NDArray[np.float64]
    face_transmittance: NDArray[np.float64]


def scene_optics(
    built: BuiltScene,
    wavelength_nm: float = SPINNING_WAVELENGTH_NM,
    *,
    ground: str = GROUND_MATERIAL,
    materials: Mapping[int, str] | None = None,
) -> SceneOptics:
    """Each object's reflectivity and transmittance from the table at ``wavelength_nm``.

    Parameters
    ----------
    built : BuiltScene
        :func:`~zbuf_occlude.sensors.scan.build_scene` of the scene; each object's material is
        :func:`material_of` its local mesh and class name, each face's its file's where that names one
        (module docstring).
    wavelength_nm : float
        The scanner's wavelength, nm; the nearest of :data:`WAVELENGTHS_NM` within
        :data:`WAVELENGTH_TOLERANCE_NM` is used.
    ground : str
        The ground's material (object id 0).
    materials : mapping of int to str, optional
        Object id → material, overriding the lookup (of every face of the object).

    Returns
    -------
    SceneOptics

    Raises
    ------
    InvalidInputError
        A wavelength far from every column, an unknown material name, an object id out of range.
    """
    column = _column(wavelength_nm)
    n_ids = len(built.objects) + 1
    names = [ground] + [material_of(built.local_meshes[i], built.objects[i - 1].class_name) for i in range(1, n_ids)]
    for oid, name in (materials or {}).items():
        if not (isinstance(oid, (int, np.integer)) and 0 <= oid < n_ids):
            raise InvalidInputError(f"materials: object id {oid!r} is not one of the scene's 0..{n_ids - 1}")
        names[int(oid)] = name
    keys = []
    for name in names:
        key = material_named(name)
        if key is None:
            raise InvalidInputError(f"unknown material {name!r}; the table holds {', '.join(MATERIALS)}")
        keys.append(key)
    rows = list(MATERIALS)
    face_material = np.array([rows.index(k) for k in keys], dtype=np.int32)[built.face_object]
    for oid in range(1, n_ids):
        found = None if oid in (materials or {}) else face_materials_of(built.local_meshes[oid])
        if found is None:
            continue
        named = np.array([rows.index(k) if (k := material_named(n)) else -1 for n in found.names], dtype=np.int32)
        if (named >= 0).any():  # the object's faces: one run, in its local mesh's order (build_scene)
            own = slice(*np.searchsorted(built.face_object, (oid, oid + 1)))
            of_file = named[found.index]
            face_material[own] = np.where(of_file >= 0, of_file, face_material[own])
    table = np.array([MATERIALS[k].reflectance[column] for k in rows]), np.array([MATERIALS[k].transmittance for k in rows])
    return SceneOptics(
        reflectivity=np.array([MATERIALS[k].reflectance[column] for k in keys]),
        transmittance=np.array([MATERIALS[k].transmittance for k in keys]),
        material=tuple(keys),
        wavelength_nm=WAVELENGTHS_NM[column],
        face_material=face_material,
        face_reflectivity=table[0][face_material],
        face_transmittance=table[1][face_material],
    )


def on_crown(built: BuiltScene, face: NDArray[np.integer]) -> NDArray[np.bool_]:
    """Whether each of ``face (H,)`` (faces of ``built.mesh``) is of a crown material (:data:`CROWN_MATERIALS`).

    Each face's material as :func:`scene_optics` gives it: its file's where that names one of the
    table, else its object's (so a tree's trunk whose file calls it "bark" is not a crown).

    Returns
    -------
    (H,) bool
    """
    rows = list(MATERIALS)
    crown = np.zeros(len(rows), dtype=bool)
    crown[[rows.index(m) for m in CROWN_MATERIALS]] = True
    return crown[scene_optics(built).face_material[np.asarray(face, dtype=np.int64)]]


def per_class(built: BuiltScene, values: Mapping[str, float], default: float = 0.0) -> NDArray[np.float64]:
    """(n_objects + 1,) float64: ``values[class]`` for each object id of ``built`` by its class name, ``default`` for the rest.

    The ground (object id 0) is the class ``"ground"``; class names match case-insensitively.
    ``scan(transmittance=per_class(built, {"bush": 0.3}))``: sub-rays go on through the bushes.

    Raises
    ------
    InvalidInputError
        A class that no object of the scene has (naming it and the scene's classes).
    """
    wanted = {str(k).lower(): float(v) for k, v in values.items()}
    classes = ["ground"] + [obj.class_name.lower() for obj in built.objects]
    missing = sorted(set(wanted) - set(classes))
    if missing:
        raise InvalidInputError(
            f"no object of the scene has the class {', '.join(map(repr, missing))}; its classes: {', '.join(sorted(set(classes)))}"
        )
    return np.array([wanted.get(c, float(default)) for c in classes])
