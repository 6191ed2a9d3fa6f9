"""Old module paths, kept importable for one release with a DeprecationWarning.

lipgen 0.1 kept every module at the top of the package (``lipgen.track``, ``lipgen.camera`` ...).
They now live in packages by pipeline stage. ``import lipgen.track`` still works: a meta-path
finder hands back the module at its new path (the same module object, so patches and
``isinstance`` checks agree) and warns once.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

MOVED: dict[str, str] = {
    "lipgen.procedural": "lipgen.mesh.procedural",
    "lipgen.mesh_io": "lipgen.mesh.io",
    "lipgen.plot_mesh": "lipgen.mesh.plot",
    "lipgen.llse": "lipgen.modes.llse",
    "lipgen.mixture": "lipgen.modes.mixture",
    "lipgen.combined": "lipgen.modes.combined",
    "lipgen.residual_prior": "lipgen.modes.residual_prior",
    "lipgen.motion": "lipgen.subject.motion",
    "lipgen.activation": "lipgen.subject.activation",
    "lipgen.face": "lipgen.subject.face",
    "lipgen.decal": "lipgen.subject.decal",
    "lipgen.camera": "lipgen.rig.camera",
    "lipgen.pinhole": "lipgen.rig.pinhole",
    "lipgen.scene": "lipgen.rig.scene",
    "lipgen.visibility": "lipgen.rig.visibility",
    "lipgen.render": "lipgen.rig.render",
    "lipgen.target": "lipgen.rig.target",
    "lipgen.generate": "lipgen.dataset.generate",
    "lipgen.calibrate": "lipgen.recon.calibrate",
    "lipgen.dots": "lipgen.recon.dots",
    "lipgen.track": "lipgen.recon.track",
    "lipgen.association": "lipgen.recon.association",
    "lipgen.pointreg": "lipgen.recon.pointreg",
    "lipgen.normalize": "lipgen.recon.normalize",
    "lipgen.headpose": "lipgen.recon.headpose",
    "lipgen.reconstruct": "lipgen.recon.steps",
    "lipgen.pipeline": "lipgen.recon.pipeline",
    "lipgen.report": "lipgen.evaluate.report",
    "lipgen._usd_author": "lipgen.usd.author",
    "lipgen._usd_read": "lipgen.usd.read",
    "lipgen.addon": "lipgen.blender",
}
"""Old module path -> new module path (``lipgen.addon.x`` follows ``lipgen.addon``)."""


def new_path(name: str) -> str | None:
    """The new path of an old module name, or None if it did not move."""
    if name in MOVED:
        return MOVED[name]
    if name.startswith("lipgen.addon."):
        return "lipgen.blender" + name[len("lipgen.addon"):]
    return None


class _Alias(importlib.abc.Loader):
    def __init__(self, target: str) -> None:
        self.target = target

    def create_module(self, spec):
        warnings.warn(f"{spec.name} has moved to {self.target}; import it from there "
                      "(the old path goes in the next release)", DeprecationWarning, stacklevel=3)
        module = importlib.import_module(self.target)
        self._spec = module.__spec__
        return module

    def exec_module(self, module) -> None:
        module.__spec__ = self._spec  # the import system set the alias's spec; keep the real one


class _MovedFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path=None, target=None):
        new = new_path(fullname)
        return None if new is None else importlib.util.spec_from_loader(fullname, _Alias(new))


def install() -> None:
    """Put the finder on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _MovedFinder) for f in sys.meta_path):
        sys.meta_path.append(_MovedFinder())
