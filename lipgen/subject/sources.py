"""The truth subject's muscle-like sources: where each action pulls (force patterns on the
mesh), the jaw's rigid motion about its hinge, the regions' stiffness, the lips' contact pairs and
the jaw's calibration.

Shared by the linear truth subject (:mod:`lipgen.subject.motion`) and the nonlinear tissue layer
(:mod:`lipgen.subject.truth`), so neither imports the other's internals.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lipgen.mesh.lipmesh import LipMesh
from lipgen.subject.activation import ACTIONS, action_index

__all__ = ["TRUTH_STIFFNESS", "ACTION_TARGETS_MM", "JAW_SHIFT_MM"]

TRUTH_STIFFNESS: dict[str, float] = {"lip": 1.4, "ridge": 3.0, "skin": 2.5, "strip": 0.05}
"""The truth subject's relative E per region (the reconstruction default differs: see
:data:`lipgen.fem.DEFAULT_STIFFNESS`). The lower lip is further softened by 25 %."""

ACTION_TARGETS_MM: dict[str, tuple[str, float]] = {
    "jaw_open": ("lower_mid", 14.0),
    "upper_lip_raiser": ("upper_left", 4.0),
    "lip_corner_puller": ("corner_left", 8.0),
    "lip_corner_depressor": ("corner_left", 5.0),
    "pucker": ("corner_left", 6.0),
    "lip_press": ("upper_mid", 3.0),
    "funneler": ("upper_mid", 4.0),
    "lower_lip_protrusion": ("lower_mid", 4.0),
    "upper_lip_raiser_left": ("upper_left", 4.0),
    "upper_lip_raiser_right": ("upper_right", 4.0),
    "lip_corner_puller_left": ("corner_left", 8.0),
    "lip_corner_puller_right": ("corner_right", 8.0),
    "lip_corner_depressor_left": ("corner_left", 5.0),
    "lip_corner_depressor_right": ("corner_right", 5.0),
    "pucker_left": ("corner_left", 5.0),
    "pucker_right": ("corner_right", 5.0),
    "funneler_left": ("upper_left", 3.5),
    "funneler_right": ("upper_right", 3.5),
    "lip_press_left": ("upper_left", 2.5),
    "lip_press_right": ("upper_right", 2.5),
    "lower_lip_depressor_left": ("lower_left", 4.0),
    "lower_lip_depressor_right": ("lower_right", 4.0),
    "lip_stretcher_left": ("corner_left", 5.0),
    "lip_stretcher_right": ("corner_right", 5.0),
    "upper_lip_roll_in": ("upper_mid", 3.0),
    "lower_lip_roll_in": ("lower_mid", 3.0),
    "upper_lip_protrusion": ("upper_mid", 7.0),
}
"""Action -> (marker, displacement in mm at activation 1 of the default subject). The jaw shifts
are rigid motions of the jaw instead (:data:`JAW_SHIFT_MM`).

The independent sources (from ``pucker_left`` on) are set from published lip kinematics: upper
and lower lip protrusion for rounded vowels reach about 5-10 mm together (Fromkin, "Lip positions
in American English vowels", Language and Speech 7, 1964; the upper lip's own share 7 mm here,
with the pucker and the mentalis adding to it); lower-lip depression and corner retraction of
3-6 mm in speech and expression (Weeden, Trotman & Faraway, "Three-dimensional analysis of facial
movement in normal adults", Cleft Palate-Craniofacial Journal 38, 2001: commissure movements of
about 5-10 mm for a maximal smile, less in speech); lip roll-in of a few mm for bilabial closure."""

JAW_SHIFT_MM = 3.0
"""Sideways shift of the jaw (mm, along x) at ``jaw_shift_left`` = 1 (``_right``: the other way)."""

_HINGE = np.array([0.0, 25.0, -85.0])  # jaw hinge (temporomandibular joints), mm, on the x axis
_GLIDE = np.array([0.0, -1.0, 2.5])  # condyle glide at full opening, mm (grows as angle^2)
_ARCH_RADIUS = 35.0  # mm, the dental arch the corners slide round (as lipgen.mesh.procedural)
_CARRY = 0.85  # share of the jaw's motion the gum imposes on the lower lip


def _gauss(X: np.ndarray, c: np.ndarray, sigma: float) -> np.ndarray:
    return np.exp(-np.sum((X - c) ** 2, axis=-1) / (2 * sigma**2))


def _region_nodes(mesh: LipMesh, names: tuple[str, ...]) -> np.ndarray:
    mask = np.zeros(mesh.n_nodes, bool)
    for name in names:
        if name in mesh.region_names:
            mask[mesh.region_nodes(name)] = True
    return mask


def _border_nodes(mesh: LipMesh) -> np.ndarray:
    """Boundary nodes whose faces are all skin: the outer border, held by the surrounding face."""
    edges = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    boundary = np.zeros(mesh.n_nodes, bool)
    boundary[uniq[count == 1].ravel()] = True
    return boundary & _region_nodes(mesh, ("skin",)) & ~_region_nodes(mesh, ("lip", "ridge", "strip"))


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def _force_patterns(mesh: LipMesh) -> dict[str, np.ndarray]:
    """Unscaled muscle-like force patterns (n, 3) per action (the jaw's depressor part for jaw_open)."""
    X = mesh.vertices
    x, y = X[:, 0], X[:, 1]
    sx = np.sign(x)
    lips = _region_nodes(mesh, ("lip", "ridge")).astype(float)
    up, lo = 0.5 + 0.5 * np.tanh(y / 1.5), 0.5 - 0.5 * np.tanh(y / 1.5)
    M = {n: X[mesh.marker_index(n)] for n in mesh.marker_names}
    outside = ~_region_nodes(mesh, ("strip",)) | lips.astype(bool)  # muscles act outside the mouth
    corner = {s: outside * _gauss(X, M[f"corner_{s}"], 6.0) for s in ("left", "right")}
    raiser = {s: lips * up * _gauss(X, M[f"upper_{s}"], 8.0) for s in ("left", "right")}
    corners = corner["left"] + corner["right"]
    mid = np.exp(-x**2 / (2 * 12.0**2))

    def field(w, fx, fy, fz):
        return w[:, None] * np.stack(np.broadcast_arrays(fx, fy, fz, w)[:3], axis=1)

    one_sided = {}
    for s in ("left", "right"):  # the same muscles on one side only
        one_sided[f"upper_lip_raiser_{s}"] = field(raiser[s], 0.0, 1.0, 0.35)
        one_sided[f"lip_corner_puller_{s}"] = field(corner[s], 0.75 * sx, 0.5, -0.45)
        one_sided[f"lip_corner_depressor_{s}"] = field(corner[s], 0.2 * sx, -1.0, 0.1)
    one_sided.update(_independent_patterns(mesh, field, lips, up, lo, corner))
    return {
        **one_sided,
        "jaw_open": field(lips * lo * _gauss(X, M["lower_mid"], 12.0), 0.0, -1.0, 0.3),
        "upper_lip_raiser": field(raiser["left"] + raiser["right"], 0.0, 1.0, 0.35),
        "lip_corner_puller": field(corners, 0.75 * sx, 0.5, -0.45),
        "lip_corner_depressor": field(corners, 0.2 * sx, -1.0, 0.1),
        "pucker": field(lips, -0.9 * x / 25.0, -0.3 * y / 10.0, 0.45),
        "lip_press": field(lips * mid, 0.0, -np.tanh(y / 2.0), -0.4),
        "funneler": field(lips * mid, -0.2 * x / 25.0, 0.7 * np.tanh(y / 2.0), 1.0),
        "lower_lip_protrusion": field((lips + 0.5) * lo * (_gauss(X, M["lower_mid"], 10.0)
                                                           + _gauss(X, M["lower_border_mid"], 10.0)),
                                      0.0, 0.45, 1.0),
    }


def _independent_patterns(mesh: LipMesh, field, lips, up, lo, corner) -> dict[str, np.ndarray]:
    """Force patterns of the independent sources (:mod:`lipgen.subject.independent`).

    A one-sided sphincter action reaches past the midline and fades on the other side (a logistic
    in x centred 3 mm across the midline), so the left and right halves are not complements of
    each other, and each side pulls in its own direction.
    """
    X = mesh.vertices
    x, y = X[:, 0], X[:, 1]
    sx = np.sign(x)
    M = {n: X[mesh.marker_index(n)] for n in mesh.marker_names}
    mid = np.exp(-x**2 / (2 * 10.0**2))
    out = {}
    for s, sign in (("left", 1.0), ("right", -1.0)):
        half = lips / (1.0 + np.exp(-(sign * x + 3.0) / 4.0))
        side = lips * np.exp(-(x - sign * 9.0) ** 2 / (2 * 8.0**2))
        out[f"pucker_{s}"] = field(half, -0.9 * x / 25.0 - 0.15 * sign, -0.3 * y / 10.0, 0.5)
        out[f"funneler_{s}"] = field(side, -0.1 * sign, 0.7 * np.tanh(y / 2.0), 1.0)
        out[f"lip_press_{s}"] = field(side, 0.0, -np.tanh(y / 2.0), -0.3)
        out[f"lower_lip_depressor_{s}"] = field(lips * lo * _gauss(X, M[f"lower_{s}"], 8.0), 0.25 * sign,
                                                -1.0, 0.45)
        out[f"lip_stretcher_{s}"] = field(corner[s], 1.0 * sx, -0.15, -0.35)
    out["upper_lip_roll_in"] = field(lips * up * mid, 0.0, -0.5, -1.0)
    out["lower_lip_roll_in"] = field(lips * lo * mid, 0.0, 0.5, -1.0)
    out["upper_lip_protrusion"] = field(lips * up * np.exp(-x**2 / (2 * 14.0**2)), 0.0, 0.25, 1.0)
    return out


def _rot_x(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros((*np.shape(angle), 3, 3))
    R[..., 0, 0] = 1.0
    R[..., 1, 1], R[..., 1, 2], R[..., 2, 1], R[..., 2, 2] = c, -s, s, c
    return R


def _jaw_rigid(X: np.ndarray, angle: np.ndarray, max_angle: float, shift=None) -> np.ndarray:
    """(b, n, 3) displacement of points ``X`` rigidly attached to the jaw, opened by ``angle`` rad
    and then shifted sideways by ``shift`` (b,) mm along x."""
    R = _rot_x(np.asarray(angle, float))
    glide = (np.asarray(angle, float) / max_angle)[:, None] ** 2 * _GLIDE
    if shift is not None:
        glide = glide + np.asarray(shift, float)[:, None] * np.array([1.0, 0.0, 0.0])
    moved = np.einsum("bij,nj->bni", R, X - _HINGE) + _HINGE + glide[:, None, :]
    return moved - X


def _wrap(X: np.ndarray, U: np.ndarray, radius: float = _ARCH_RADIUS) -> np.ndarray:
    """Positions ``X + U`` with the tangential part of ``U`` taken along the dental-arch cylinder.

    Identity to first order in ``U``; a corner moved sideways by s mm also moves s²/(2ρ) back.
    """
    px, pz = X[:, 0], X[:, 2] + radius
    rho0, phi0 = np.hypot(px, pz), np.arctan2(px, pz)
    e_phi = np.stack([np.cos(phi0), np.zeros_like(phi0), -np.sin(phi0)], axis=1)
    e_rho = np.stack([np.sin(phi0), np.zeros_like(phi0), np.cos(phi0)], axis=1)
    u_phi, u_rho = np.einsum("...ni,ni->...n", U, e_phi), np.einsum("...ni,ni->...n", U, e_rho)
    phi, rho = phi0 + u_phi / rho0, rho0 + u_rho
    return np.stack([rho * np.sin(phi), X[:, 1] + U[..., 1], rho * np.cos(phi) - radius], axis=-1)


def _contact_pairs(mesh: LipMesh) -> np.ndarray:
    """(p, 2) [upper, lower] node pairs of the inner contour: ridge nodes that mirror each other
    under y -> -y (the rest contour is a lens symmetric about the mouth line), corners excluded."""
    from scipy.spatial import cKDTree

    ridge = np.flatnonzero(_region_nodes(mesh, ("ridge",)))
    V = mesh.vertices[ridge]
    dist, j = cKDTree(V).query(V * np.array([1.0, -1.0, 1.0]))
    ok = (dist < 1e-6) & (V[:, 1] > 1e-6)
    return np.stack([ridge[ok], ridge[j[ok]]], axis=1)


def _calibrate_jaw(subject, lower_lip: np.ndarray, target_mm: float):
    """``subject`` (a :class:`~lipgen.subject.motion.Subject`) with the gum's carry set so the lower
    lip follows the jaw by ``_CARRY``, then the opening angle so that ``jaw_open = 1`` moves the
    lower-lip marker by ``target_mm``."""
    mesh = subject.mesh
    ref = mesh.marker_index("lower_mid")
    probe = np.deg2rad(10.0)
    rigid = _jaw_rigid(mesh.vertices, np.array([probe]), probe)[0]
    base = replace(subject, jaw_max_angle=probe)
    no_carry = base.jaw_displacement([probe])[0, ref]
    unit = replace(base, carry=lower_lip[:, None] * np.ones(3)).jaw_displacement([probe])[0, ref] - no_carry
    # least-squares gain so that no_carry + gain * unit ~= _CARRY * rigid at the marker
    gain = float(np.dot(unit, _CARRY * rigid[ref] - no_carry) / np.dot(unit, unit))
    carry = gain * lower_lip[:, None] * np.ones(3)
    jaw_col = action_index("jaw_open")
    lo, hi = np.deg2rad(1.0), np.deg2rad(35.0)
    for _ in range(40):  # bisection: the response is monotone in the angle
        mid = 0.5 * (lo + hi)
        trial = replace(subject, carry=carry, jaw_max_angle=mid)
        act = np.zeros((1, len(ACTIONS)))
        act[0, jaw_col] = 1.0
        moved = np.linalg.norm(trial.displacements(act)[0, ref])
        lo, hi = (mid, hi) if moved < target_mm else (lo, mid)
    return replace(subject, carry=carry, jaw_max_angle=0.5 * (lo + hi))
