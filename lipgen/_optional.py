"""Optional dependencies, imported on demand with a message that says how to install them."""

from __future__ import annotations

import importlib
from types import ModuleType

from lipgen.errors import MissingDependencyError

__all__ = ["require"]

_HINTS = {
    "pxr": "pip install 'lipgen[usd]'  (package usd-core)",
    "pyrender": "pip install 'lipgen[render]'  (pyrender, PyOpenGL; needs Mesa EGL: "
    "apt install libegl1 libgl1-mesa-dri)",
    "cv2": "pip install 'lipgen[vision]'  (opencv-python-headless)",
    "bpy": "pip install 'lipgen[blender]'  (bpy==5.0.1 needs Python 3.11)",
    "skfem": "pip install scikit-fem",
    "imageio_ffmpeg": "pip install 'lipgen[vision]'  (imageio-ffmpeg, which brings its own ffmpeg)",
    "cvxopt": "pip install 'lipgen[fast]'  (cvxopt, for the CHOLMOD sparse Cholesky)",
    "ray": "pip install 'lipgen[cluster]'  (ray[default], for lipgen campaign)",
    "pyarrow": "pip install 'lipgen[cluster]'  (pyarrow, for campaign.parquet)",
    "fsspec": "pip install 'lipgen[cluster]'  (fsspec, for campaigns into object stores)",
    "pocketsphinx": "pip install 'lipgen[speech]'  (pocketsphinx, with its en-US models)",
}


def require(name: str, purpose: str) -> ModuleType:
    """Import module ``name`` or raise :class:`MissingDependencyError` explaining the fix.

    Parameters
    ----------
    name : str
        Importable module name, e.g. ``"pxr"`` or ``"pyrender"``.
    purpose : str
        What the caller needs it for, shown in the message.
    """
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        hint = _HINTS.get(name.split(".")[0], f"pip install {name}")
        raise MissingDependencyError(
            f"{purpose} needs the optional module {name!r}, which could not be imported "
            f"({exc}). Install it with: {hint}"
        ) from exc
