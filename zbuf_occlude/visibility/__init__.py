"""Hidden surface removal (HSR): every method behind one signature, in a registry.

Importing this package registers the built-in methods.
"""

from . import oracle, zbuffer  # noqa: F401  (import registers the methods)
from .registry import DEFAULT_SELF_HIT_TOLERANCE, available_methods, register, visible_mask

__all__ = ["visible_mask", "available_methods", "register", "DEFAULT_SELF_HIT_TOLERANCE"]
