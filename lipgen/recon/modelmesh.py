"""The reconstruction model's mesh from its source string (kept apart from the pipeline, which
re-exports it, so that the steps after it can name a mesh without importing the pipeline)."""

from __future__ import annotations

from lipgen.mesh.lipmesh import LipMesh

__all__ = ["model_mesh"]


def model_mesh(source: str = "lip_mesh(0)") -> LipMesh:
    """The reconstruction model's mesh: ``"lip_mesh(R)"`` or a path to a saved :class:`LipMesh`."""
    if source.startswith("lip_mesh(") and source.endswith(")"):
        from lipgen.mesh.procedural import lip_mesh

        return lip_mesh(int(source[len("lip_mesh("):-1]))
    return LipMesh.load(source)
