"""Mesh files → normalised z-up trimesh: formats, units and up axes, discovery, layouts, real sizes.

:mod:`.load` (:func:`load_mesh`, :func:`normalize_mesh`), :mod:`.formats` (the table of formats,
suffix → reader and checks, a module per format family), :mod:`.scene` (glTF/COLLADA scenes: units,
up axes), :mod:`.inputs` (the input files of a run, meshes and point sets: their kinds, discovery,
layouts → labels, the numbered objects of a data set), :mod:`.paths` (what a path says: printable
text, splits, class and split), :mod:`.sizes` (real object sizes per class), :mod:`.cache` (per-mesh
caches of the renderers).
trimesh and pycollada do the parsing; each name is imported from its module when first used, so
``import zbuf_occlude.mesh`` loads no trimesh.
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach(
    __name__,
    submod_attrs={
        "load": ["load_mesh", "normalize_mesh", "clean_mesh", "degenerate_faces",
                 "DEGENERATE_AREA_RTOL", "MAX_ABS_COORDINATE", "METADATA_KEY"],
        "formats": ["SUPPORTED_EXTENSIONS", "EXTENSIONS_TEXT"],
        "inputs.discovery": ["find_meshes", "scan_meshes", "walk_mesh_files", "MeshScan", "SkippedInput", "non_utf8_reason"],
        "paths": ["printable_path", "class_and_split", "name_set", "SPLITS", "DEFAULT_SPLIT"],
        "inputs.plan": ["FarmObject", "ObjectScan", "scan_inputs", "scan_paths", "objects_from_paths", "discover_objects"],
        "scene": ["UP_CHOICES", "resolve_up", "up_rotation"],
    },
)  # fmt: skip
