"""Hidden surface removal (HSR): every method behind one signature, in a registry.

The built-in methods register themselves when their modules are imported, which the registry
does the first time a method is looked up (:data:`~zbuf_occlude.visibility.registry.BUILTIN_MODULES`).
"""

from zbuf_occlude.defaults import DEFAULT_SELF_HIT_TOLERANCE
from zbuf_occlude.visibility.registry import MethodInfo, available_methods, method_info, register, visible_mask
from zbuf_occlude.visibility.session import VisibilitySession

__all__ = [
    "visible_mask", "VisibilitySession", "available_methods", "method_info", "MethodInfo", "register",
    "DEFAULT_SELF_HIT_TOLERANCE",
]  # fmt: skip
