"""The on-disk data set: its layout, its schema, the reader and ``verify``.

:mod:`.layout` (file and folder names, columns: what writers and readers share), :mod:`.storage`
(one class per storage kind, in a table the farm's writer and the reader share), :mod:`.schema`
(the card, the manifest and the shards, checked with pydantic), :mod:`.index` (which shard row each
sample is), :mod:`.reader` (:class:`OccludedDataset`: every storage and format as one sequence of samples),
:mod:`.sample_files` (one-sample ``.npz``/``.ply`` files), :mod:`.verify` (every file against its
SHA-256 and the schema).  Each name is imported from its module when first used.
"""

import lazy_loader as _lazy

__getattr__, __dir__, __all__ = _lazy.attach(
    __name__,
    submod_attrs={
        "reader": ["OccludedDataset"],
        "storage": ["STORAGE_KINDS", "storage_kind", "reconstruct_samples", "unpack_visible"],
        "index": ["samples_per_pose", "sample_index"],
        "layout": ["FORMAT_VERSION", "CARD_FILE", "MANIFEST_FILE", "SHAPE_NAMES_FILE", "SHARD_DIR", "STORAGE_MODES",
                   "file_list_name"],
        "verify": ["VerifyReport", "verify_dataset"],
    },
)  # fmt: skip
