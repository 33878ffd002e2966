"""Procedural object families: seeded, parameterised generators of the outdoor objects real scans hold.

Bare trunks, shrubs, clipped hedges, trees with a crown of leaf clusters, utility poles (crossarms, insulators,
short wire spans), street lights (arms, heads), sign posts (several plates per post) and
pedestrians (standing or walking, coats and bags), each
composed of ``trimesh.creation`` parts in real size (metres, z up, standing on z = 0), each
parameter range cited in its module's docstring.

:mod:`.registry` holds the table (:data:`FAMILIES`: name → :class:`Family`); :mod:`.parts` the
primitives; one module per family; :mod:`.write` writes N of a family into a class folder with a
manifest of each file's parameters (``zbuf-occlude families``).
"""

from zbuf_occlude.mesh.families.registry import FAMILIES, Family, family_rng, get_family
from zbuf_occlude.mesh.families.write import MANIFEST_SUFFIX, FamilyRun, write_family

__all__ = ["FAMILIES", "MANIFEST_SUFFIX", "Family", "FamilyRun", "family_rng", "get_family", "write_family"]
