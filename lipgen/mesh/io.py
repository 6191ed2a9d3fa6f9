"""Write a :class:`~lipgen.mesh.LipMesh` for other tools, and read it back with its annotations.

OBJ and PLY hold only the geometry, so :func:`write_mesh` puts the regions, anchors, markers and
nose in a JSON sidecar beside the file (``lips.obj`` -> ``lips.obj.json``); :func:`read_mesh`
reads both. ``.npz`` (:meth:`LipMesh.save`) holds everything in one file. STL is refused for
writing: it stores no shared vertices, so node indices (anchors, markers) cannot survive it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from lipgen._io import atomic_path, atomic_write_json
from lipgen.errors import MeshError
from lipgen.mesh.lipmesh import LipMesh

__all__ = ["MESH_SUFFIXES", "read_mesh", "sidecar_path", "write_mesh"]

MESH_SUFFIXES = (".obj", ".ply", ".npz")
"""File suffixes :func:`read_mesh` and :func:`write_mesh` handle (STL reads too)."""
_SIDECAR_KIND, _SIDECAR_SCHEMA = "lipgen.LipMesh.sidecar", 1


def sidecar_path(path: str | os.PathLike) -> Path:
    """The JSON sidecar of an OBJ or PLY file: the same name with ``.json`` appended."""
    p = Path(path)
    return p.with_name(p.name + ".json")


def _check_suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix == ".stl":
        raise ValueError(f"cannot write {path}: STL stores no shared vertices, so the anchors and "
                         "markers (node indices) would be lost; use .obj, .ply or .npz")
    if suffix not in MESH_SUFFIXES:
        raise ValueError(f"cannot write {path}: unknown extension {suffix!r}; use one of {MESH_SUFFIXES}")
    return suffix


def write_mesh(mesh: LipMesh, path: str | os.PathLike, overwrite: bool = False) -> list[Path]:
    """Write ``mesh`` to ``.obj``/``.ply`` (+ JSON sidecar) or ``.npz``, atomically.

    Vertex order is kept exactly, so the sidecar's node indices stay valid. Coordinates are
    millimetres in the model frame (+x subject's left, +y up, +z out of the face).

    Parameters
    ----------
    mesh : LipMesh
    path : path
        Destination; its extension chooses the format.
    overwrite : bool
        Replace existing files; otherwise an existing destination raises ``FileExistsError``.

    Returns
    -------
    list of Path
        The files written.
    """
    p = Path(path)
    suffix = _check_suffix(p)
    outputs = [p] if suffix == ".npz" else [p, sidecar_path(p)]
    if not overwrite:
        for out in outputs:
            if out.exists():
                raise FileExistsError(f"{out} exists; choose another name or allow overwriting")
    if suffix == ".npz":
        mesh.save(p)
        return outputs
    with atomic_path(p) as tmp:
        if suffix == ".obj":
            _write_obj(tmp, mesh)
        else:
            _write_ply(tmp, mesh)
    atomic_write_json(outputs[1], _sidecar(mesh, p.name))
    return outputs


def _write_obj(path: Path, mesh: LipMesh) -> None:
    head = (f"# lipgen mesh {mesh.name!r}: {mesh.n_nodes} vertices, {mesh.n_faces} triangles, "
            "millimetres, +x subject's left, +y up, +z out of the face\n")
    with open(path, "w") as fh:
        fh.write(head)
        np.savetxt(fh, mesh.vertices, fmt="v %.17g %.17g %.17g")
        np.savetxt(fh, mesh.faces + 1, fmt="f %d %d %d")


def _write_ply(path: Path, mesh: LipMesh) -> None:
    header = ("ply\nformat binary_little_endian 1.0\ncomment lipgen mesh, millimetres\n"
              f"element vertex {mesh.n_nodes}\nproperty double x\nproperty double y\nproperty double z\n"
              f"element face {mesh.n_faces}\nproperty list uchar int vertex_indices\nend_header\n")
    face = np.zeros(mesh.n_faces, dtype=[("n", "u1"), ("v", "<i4", (3,))])
    face["n"], face["v"] = 3, mesh.faces
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(np.ascontiguousarray(mesh.vertices, dtype="<f8").tobytes())
        fh.write(face.tobytes())


def _sidecar(mesh: LipMesh, geometry_name: str) -> dict:
    return {
        "kind": _SIDECAR_KIND, "schema": _SIDECAR_SCHEMA, "geometry": geometry_name, "units": "mm",
        "frame": "+x subject's left, +y up, +z out of the face", "name": mesh.name,
        "n_nodes": mesh.n_nodes, "n_faces": mesh.n_faces, "topology_id": mesh.topology_id,
        "region_names": list(mesh.region_names), "regions": mesh.regions.tolist(),
        "anchors": mesh.anchors.tolist(),
        "markers": [[n, int(i)] for n, i in zip(mesh.marker_names, mesh.markers, strict=True)],
        "nose": mesh.nose.tolist(),
    }


def read_mesh(path: str | os.PathLike) -> LipMesh:
    """Read a mesh written by :func:`write_mesh` (``.npz``, or OBJ/PLY with its JSON sidecar).

    Raises
    ------
    MeshError
        If the sidecar is missing, unreadable, or does not fit the geometry (node or face
        counts differ, e.g. the OBJ was edited after export).
    """
    p = Path(path)
    if p.suffix.lower() == ".npz":
        return LipMesh.load(p)
    side = sidecar_path(p)
    if not side.is_file():
        raise MeshError(f"{p} has no sidecar {side.name} with regions, anchors and markers; load the "
                        "bare geometry with LipMesh.from_file(path, anchors=..., markers=...)")
    try:
        meta = json.loads(side.read_text())
        if meta.get("kind") != _SIDECAR_KIND or meta.get("schema") != _SIDECAR_SCHEMA:
            raise ValueError(f"kind/schema {meta.get('kind')!r}/{meta.get('schema')!r}, expected "
                             f"{_SIDECAR_KIND!r}/{_SIDECAR_SCHEMA}")
        names, idx = zip(*meta["markers"], strict=True) if meta["markers"] else ((), ())
        mesh = LipMesh.from_file(p, anchors=meta["anchors"], markers=list(idx), marker_names=names,
                                 regions=meta["regions"], region_names=tuple(meta["region_names"]),
                                 nose=meta["nose"])
    except (KeyError, TypeError, json.JSONDecodeError) as exc:
        raise MeshError(f"sidecar {side} is unreadable: {exc!r}") from exc
    except ValueError as exc:
        if isinstance(exc, MeshError):
            raise
        raise MeshError(f"{p} does not fit its sidecar {side.name}: {exc}") from exc
    if (mesh.n_nodes, mesh.n_faces) != (meta["n_nodes"], meta["n_faces"]):
        raise MeshError(f"{p} has {mesh.n_nodes} vertices and {mesh.n_faces} faces but its sidecar "
                        f"describes {meta['n_nodes']} and {meta['n_faces']}; was it edited after export?")
    return mesh
