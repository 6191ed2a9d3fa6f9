"""Global stiffness: per-face E from regions, sparse assembly, and the grounding checks.

The checks run before any factorisation so that a mesh that cannot be grounded is reported with
what is wrong and how to fix it, instead of as a failed or meaningless solve:

* no anchors at all;
* nodes that no chain of faces connects to an anchor (named in the message);
* anchors that leave a rigid motion free. For this element only some rigid motions cost no
  strain: the three translations always, and a rotation about the normal of a flat patch
  (eq 2.13 penalises out-of-plane tilts, so rotations of a curved mesh are not free). Two
  anchors hold a flat sheet (the thesis's Fig 2-2 fixes two corners); a rotation about the line
  through collinear anchors is caught only where it really costs nothing.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from lipgen._validate import as_float_array
from lipgen.errors import SingularStiffnessError
from lipgen.fem.element import element_stiffness
from lipgen.mesh.lipmesh import LipMesh

__all__ = ["DEFAULT_STIFFNESS", "face_stiffness", "assemble_stiffness", "check_grounding",
           "element_dofs"]

log = logging.getLogger(__name__)

DEFAULT_STIFFNESS: dict[str, float] = {"lip": 1.0, "ridge": 2.0, "strip": 0.3, "skin": 1.5}
"""Relative E per region (thesis §2.4). ``lip`` 1.0 and ``ridge`` 2.0 are the thesis's values.

``strip`` (the thesis says only "low") is 0.3. With the thesis's grounding (only the strip's
far end anchored, ``lip_mesh(anchor_border=False)``) the strip is the lips' only attachment to
the head and its E sets how much the whole mouth swings on it: pulling the three lower-lip
markers down, the upper lip midline follows by 89-93% at 0.01, 43-55% at 0.1, 19-28% at 0.3 and
5-9% at 1.0 (range over skin E 1-3). At 0.3 the lower lip moves mostly on its own while the
upper lip still rides freely on the strip ("relatively free deformation of the lips while still
maintaining the necessary rigid constraints"). With the default lips' skin border anchored too,
the strip matters less: a unit upward pull on the upper-lip markers raises the midline 1.09,
0.97, 0.76 mm at strip E 0.1, 0.3, 1.0 (skin 1.0). ``skin`` (the thesis's mesh has none) is 1.5:
perioral skin taken a little stiffer than the lip, so the lips rather than the surrounding skin
take up a deformation (the lower lip's pull-down drops from 1.72 to 1.34 mm going from 1.0 to
1.5)."""


def face_stiffness(mesh: LipMesh, stiffness=None) -> np.ndarray:
    """Per-face E, ``(m,) float``, from a region mapping or an array.

    Parameters
    ----------
    mesh : LipMesh
    stiffness : None, mapping or (m,) float
        ``None`` uses :data:`DEFAULT_STIFFNESS`. A mapping ``{region name: E}`` overrides the
        defaults for the regions it names; a region of the mesh with no value is an error, as is
        a name that is neither one of the mesh's regions nor a default region (a typo).
    """
    m = mesh.n_faces
    if stiffness is None or isinstance(stiffness, Mapping):
        given = dict(stiffness or {})
        unknown = sorted(set(given) - set(mesh.region_names) - set(DEFAULT_STIFFNESS))
        if unknown:
            raise ValueError(f"stiffness names unknown region(s) {unknown}; this mesh has regions "
                             f"{mesh.region_names}")
        table = {**DEFAULT_STIFFNESS, **given}
        used = [mesh.region_names[r] for r in np.unique(mesh.regions)]
        missing = [r for r in used if r not in table]
        if missing:
            raise ValueError(f"no stiffness for region(s) {missing} of mesh {mesh.name!r}; pass "
                             f"stiffness={{{missing[0]!r}: E, ...}} or an (m,) array with m = {m}")
        values = np.array([float(table.get(r, np.nan)) for r in mesh.region_names])
        E = values[mesh.regions]
        name = "stiffness (per region)"
    else:
        E = as_float_array(stiffness, "stiffness", finite=False)
        if E.shape != (m,):
            raise ValueError(f"stiffness must be a mapping region -> E or an array of shape ({m},) "
                             f"(one E per face), got shape {E.shape}")
        name = "stiffness"
    bad = ~np.isfinite(E) | (E <= 0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{name} must be finite and positive for every face; face {i} (region "
                         f"{mesh.region_names[mesh.regions[i]]!r}) has E = {E[i]!r}; "
                         f"{int(bad.sum())} of {m} faces are bad")
    return E


def element_dofs(faces: np.ndarray) -> np.ndarray:
    """(m, 9) global DOF indices of each face, node-major ``(x1, y1, z1, x2, ...)``."""
    faces = np.asarray(faces, np.int64)
    return (3 * faces[:, :, None] + np.arange(3)).reshape(len(faces), 9)


def assemble_stiffness(mesh: LipMesh, E=None, nu: float = 0.01,
                       out_of_plane: str = "thesis") -> sp.csr_matrix:
    """The global (ungrounded) stiffness K, ``(3n, 3n)`` sparse CSR, eq 2.8.

    Parameters
    ----------
    mesh : LipMesh
    E : None, float, mapping or (m,) float
        Per-face E; anything :func:`face_stiffness` accepts, or a scalar for a uniform sheet.
    nu : float
        Poisson's ratio (0.01 in the thesis).
    out_of_plane : {"thesis", "laplacian"}
        Form of the out-of-plane block (see :mod:`lipgen.fem.element`).
    """
    if not isinstance(mesh, LipMesh):
        raise TypeError(f"mesh must be a lipgen.LipMesh, got {type(mesh).__name__}")
    scalar = E is not None and not isinstance(E, Mapping) and np.ndim(E) == 0
    E = face_stiffness(mesh, np.full(mesh.n_faces, float(E)) if scalar else E)
    ke = element_stiffness(mesh.vertices[mesh.faces], E, nu, out_of_plane)
    dof = element_dofs(mesh.faces)
    if mesh.n_dofs < 2**31:
        dof = dof.astype(np.int32)  # scipy's own index type: no conversion, a faster COO -> CSR
    rows = np.repeat(dof, 9, axis=1).ravel()
    cols = np.tile(dof, (1, 9)).ravel()
    n = mesh.n_dofs
    K = sp.csr_matrix((ke.ravel(), (rows, cols)), shape=(n, n))  # duplicates are summed
    K.sum_duplicates()
    return K


def _node_graph(mesh: LipMesh) -> sp.csr_matrix:
    f = mesh.faces
    i = np.concatenate([f[:, 0], f[:, 1], f[:, 2]])
    j = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    return sp.csr_matrix((np.ones(len(i)), (i, j)), shape=(mesh.n_nodes, mesh.n_nodes))


def _rigid_modes(points: np.ndarray) -> np.ndarray:
    """(3p, 6) infinitesimal rigid motions of ``points``: 3 translations, 3 rotations about the
    centroid, the rotations scaled by the RMS radius so all six columns have comparable size."""
    c = points - points.mean(axis=0)
    radius = max(float(np.sqrt((c**2).sum(axis=1).mean())), 1e-300)
    R = np.zeros((len(points), 3, 6))
    R[:, [0, 1, 2], [0, 1, 2]] = 1.0
    for a in range(3):
        axis = np.zeros(3)
        axis[a] = 1.0
        R[:, :, 3 + a] = np.cross(axis, c) / radius
    return R.reshape(-1, 6)


def check_grounding(mesh: LipMesh, K: sp.spmatrix) -> None:
    """Raise :class:`SingularStiffnessError` if the anchors cannot hold the mesh still.

    Parameters
    ----------
    mesh : LipMesh
    K : (3n, 3n) sparse
        The assembled (ungrounded) stiffness of ``mesh``.
    """
    anchors = mesh.anchors
    if len(anchors) == 0:
        raise SingularStiffnessError(
            f"mesh {mesh.name!r} has no anchors, so K cannot be grounded (it is singular: the mesh "
            "can move rigidly without strain). Give LipMesh(anchors=[...]) the node indices fixed "
            "to the head: at least two, not all on one line (the default lips anchor the far end "
            "of the strip)")
    n_comp, label = connected_components(_node_graph(mesh), directed=False)
    held = np.zeros(n_comp, bool)
    held[label[anchors]] = True
    loose = np.flatnonzero(~held[label])
    if len(loose):
        raise SingularStiffnessError(
            f"{len(loose)} of {mesh.n_nodes} nodes of mesh {mesh.name!r} are not connected through "
            f"faces to any anchor, e.g. nodes {loose[:10].tolist()}; K is singular there. Anchor "
            f"at least two nodes of every separate piece, or remove the unattached pieces")
    K = sp.csr_matrix(K)
    for comp in range(n_comp):
        nodes = np.flatnonzero(label == comp)
        _check_rigid_motions(mesh, K, nodes, np.intersect1d(anchors, nodes))


def _check_rigid_motions(mesh: LipMesh, K: sp.csr_matrix, nodes: np.ndarray,
                         anchors: np.ndarray) -> None:
    """Every rigid motion of this piece that costs no strain must move some anchor."""
    pts = mesh.vertices[nodes]
    R = _rigid_modes(pts)
    dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    Kc = K[dofs][:, dofs]
    H = R.T @ (Kc @ R)
    H = 0.5 * (H + H.T)
    w, vec = np.linalg.eigh(H)
    # A rigid mode of unit size per node costs ~ trace(Kc) when it strains the mesh.
    free = vec[:, w <= 1e-9 * max(float(Kc.diagonal().sum()), 1e-300)]
    if free.shape[1] == 0:
        where = np.searchsorted(nodes, anchors)
        _warn_if_held_by_tilt_penalty(mesh, R.reshape(len(nodes), 3, 6)[where].reshape(-1, 6), anchors)
        return
    where = np.searchsorted(nodes, anchors)
    Ra = R.reshape(len(nodes), 3, 6)[where].reshape(-1, 6)
    _warn_if_held_by_tilt_penalty(mesh, Ra, anchors)
    _, s, vt = np.linalg.svd(Ra @ free, full_matrices=True)
    s = np.concatenate([s, np.zeros(free.shape[1] - len(s))])
    if s.min() > 1e-6:
        return
    mode = free @ vt[np.argmin(s)]
    rot = mode[3:]
    if np.linalg.norm(rot) < 1e-6:
        what = "translate"
    else:
        axis = rot / np.linalg.norm(rot)
        axis = np.round(axis * np.sign(axis[np.argmax(np.abs(axis))]), 3) + 0.0  # +0.0: no "-0.0"
        what = f"rotate about an axis along {axis.tolist()}"
    raise SingularStiffnessError(
        f"the anchors {anchors[:10].tolist()} do not hold mesh {mesh.name!r} still: the piece with "
        f"node {int(nodes[0])} can {what} without strain, so K is singular. This happens with a "
        f"single anchor, or anchors all on one line across a flat patch; add an anchor off that "
        f"line (at least two for a flat sheet, three not on one line to be safe)")


def _warn_if_held_by_tilt_penalty(mesh: LipMesh, Ra: np.ndarray, anchors: np.ndarray) -> None:
    """Log a warning when the anchors alone do not block every rigid motion (one anchor, or all
    on a line): such a mesh is held only because eq 2.13 charges out-of-plane tilts."""
    sv = np.linalg.svd(Ra, compute_uv=False)
    if len(sv) < 6 or sv[5] <= 1e-6 * sv[0]:
        log.warning("the anchors %s of mesh %r are a single node or all on one line: the mesh can "
                    "rotate about that line, and is held only by the element's out-of-plane term "
                    "(eq 2.13), a weak and artificial restraint. Anchor at least three nodes not on "
                    "one line", anchors[:10].tolist(), mesh.name)
