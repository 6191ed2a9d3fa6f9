"""Training shapes for a rig's modes from a lipgen dataset folder (``lipgen generate``).

A dataset records the synthetic subject's true vertices per frame (model frame, mm) on its own
mesh, usually ``lip_mesh(1)``. The procedural meshes are nested (node i of ``lip_mesh(r)`` is
node i of every finer one), so a rig on ``lip_mesh(r)`` with ``r`` no finer than the dataset's
mesh takes the first nodes of each frame. Any other rig must have the dataset mesh's topology.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lipgen.blender.speech import lips_resolution
from lipgen.errors import TopologyMismatchError

__all__ = ["dataset_displacements"]


def dataset_displacements(path: str | os.PathLike, n_nodes: int, topology_id: str) -> np.ndarray:
    """(F, n, 3) true displacements (mm, model frame) of a dataset, on a rig's ``n_nodes``.

    Parameters
    ----------
    path : path
        The dataset folder, or its ``manifest.json``.
    n_nodes, topology_id : int, str
        The rig mesh's node count and :attr:`lipgen.LipMesh.topology_id`.

    Raises
    ------
    lipgen.DatasetError
        If the folder is not a complete dataset.
    lipgen.TopologyMismatchError
        If the rig is neither the dataset's mesh nor a coarser procedural lips mesh.
    """
    from lipgen.dataset.layout import Dataset

    p = Path(path)
    ds = Dataset(p.parent if p.name == "manifest.json" else p)
    mesh = ds.mesh
    if mesh.topology_id != topology_id:
        rig_r = lips_resolution(n_nodes, topology_id)
        data_r = lips_resolution(mesh.n_nodes, mesh.topology_id)
        if rig_r is None or data_r is None or rig_r > data_r:
            raise TopologyMismatchError(
                f"the dataset's mesh ({mesh.n_nodes} nodes, topology {mesh.topology_id}) is not "
                f"this mesh ({n_nodes} nodes, topology {topology_id}), nor a finer procedural "
                "lips mesh of which it is a part; train on a dataset made for this mesh")
    rest = mesh.vertices[:n_nodes]
    ds.require_truth("training on a dataset's true motion")
    return np.array([ds.truth(i)["vertices"][:n_nodes] - rest for i in range(len(ds))])
