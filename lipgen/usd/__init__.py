"""USD export of lip animation (UsdSkel blend shapes and baked points) and read-back.

* :mod:`~lipgen.usd.export`: :func:`export_usd`, the public entry point.
* :mod:`~lipgen.usd.author`: authoring the stage (imports pxr when used).
* :mod:`~lipgen.usd.read`: :func:`read_animation` through UsdSkel, and :func:`validate`.
"""

from lipgen.usd.export import (
    BAKED_POINTS,
    BLEND_SHAPES,
    ENCODING_SET,
    EXTENSIONS,
    UsdAnimation,
    ValidationIssue,
    export_usd,
    read_animation,
    validate,
)

__all__ = ["export_usd", "read_animation", "validate", "UsdAnimation", "ValidationIssue",
           "EXTENSIONS", "ENCODING_SET", "BLEND_SHAPES", "BAKED_POINTS"]
