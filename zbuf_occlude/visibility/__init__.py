"""Hidden surface removal (HSR): every method behind one signature, in a registry.

Importing this package registers the built-in methods.
"""

# Importing a method's module registers it: image space (zbuffer), the exact oracle, the
# paper's object-space methods (§3.3-3.6) and peers (naive-zbuffer, open3d-*).
from . import auto, embree_fast, gpu_exact, object_space, occupancy, oracle, peers, vertex, zbuffer  # noqa: F401
from .registry import DEFAULT_SELF_HIT_TOLERANCE, MethodInfo, available_methods, method_info, register, visible_mask

__all__ = ["visible_mask", "available_methods", "method_info", "MethodInfo", "register", "DEFAULT_SELF_HIT_TOLERANCE"]
