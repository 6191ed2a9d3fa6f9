"""The default procedural lips: a smooth parametric surface, meshed at nested resolutions.

Geometry (millimetres, model frame: +x subject's left, +y up, +z out of the face, origin at the
centre of the mouth opening at rest)
------------------------------------------------------------------------------------------------
The lips and the skin around them form an annulus around the mouth opening, parametrised by an
angle ``theta`` around the mouth (0 at the subject's left corner, pi/2 at the upper midline) and a
ring coordinate ``s`` in [0, 6] from the inner contour outwards:

- ``s = 0``: the inner contour of the lips, a thin oval 50 mm wide (corner to corner) with a
  3 mm interlabial gap at the midline (lips slightly parted at rest), its corners rounded only
  on the scale of a fine element;
- ``0 <= s <= 1``: the inner ridge (region ``"ridge"``, about 2 mm wide), where the lip rolls
  into the mouth;
- ``1 <= s <= 3``: the vermilion (region ``"lip"``); ``s = 3`` is the vermilion border, with
  Cupid's bow (peaks at x = +-5.2 mm, a 1.6 mm dip at the midline), an upper vermilion about
  7.5 mm high and a fuller lower vermilion 10 mm high, thinning to 5 mm round the corners;
- ``3 <= s <= 6``: skin (region ``"skin"``) out to an oval border 72 mm wide running from just
  under the nose (y = +20) down over the chin (y = -40).

The rings 1-3 are offsets of the inner contour whose direction fans round the mouth corners, so
the elements there stay well shaped (smallest angle about 12 degrees at every resolution).

Depth follows the curve of the dental arch, ``z = -x**2 / 70`` (the corners sit about 12 mm behind
the most protruding vermilion), plus a midline profile that fades towards the corners: the vermilion protrudes
about 3 mm, the skin recedes under the nose and at the mentolabial sulcus and comes forward again
at the chin.

The low-stiffness strip (region ``"strip"``, thesis §2.4) continues the upper lip's surface over
its inner contour, between the nodes just inside the corners, up and back into the mouth along
the inside of the upper lip, like the labial mucosa running to the upper gum: 10 mm up and 12 mm
back at the midline. Its normals, continuing the orientation of the outer surface over the
ridge, point out of the lip tissue, i.e. into the mouth (towards the teeth).

Anchors
-------
By default the anchors are the nodes at the far end of the strip (as in the thesis) *and* the
outer border of the skin. The far end of the strip follows the upper gum along the dental arch,
a curve bent in both y and z, so on its own it is not collinear and removes all six rigid
motions; the thesis grounds its mesh only there, and ``anchor_border=False`` reproduces that.
We also fix the skin border because this mesh is a patch cut out of a face: at its border the
skin carries on into the rest of the face, which after the thesis's rigid normalisation (nose
subtracted, lip planes aligned) moves far less than the lips. Without it, everything below the
corners (lower lip, chin skin) hangs from the soft strip through the mouth corners only, and the
grounded stiffness has near-rigid swinging modes: at resolution 1, with the physics' defaults,
its condition number is 7e4 instead of 2e3, and the minimum-norm force that moves the two corners
3 mm apart (eq 4.3) swings the lower face by 23 mm instead of deforming the lips by 5 mm. The
price is that the chin border does not follow the jaw; goals on the lower lip are still reached
exactly, with the chin skin stretching between the lip and the border.

Resolution
----------
At resolution 0 the mesh has 24 nodes around each ring, 7 rings and a 3-row strip: 201 nodes and
348 faces (thesis: 204 and 336). Each step halves the parameter spacing in both directions, so
there are exactly 4 times as many faces, every node of resolution r is node of the same index
and position at resolution r + 1 (the first ``n_r`` nodes), and new nodes lie on the same surface:
the rings of resolution 0 are analytic closed curves in ``theta``, joined by a cubic spline in
``s`` (and in the strip's row coordinate). Markers, anchors of resolution 0 and the nose are
therefore the same points at every resolution.

Markers (thesis Fig 3-1, whose picture the text does not carry; this layout follows its rules:
the lips are sampled, densest near the corners where motion is least linear, all on the visible
vermilion so that both views of the camera-mirror rig see them)
------------------------------------------------------------------------------------------------
The first eight (Table 5.1's sparse set) go round the mouth every 45 degrees: mid upper and lower
vermilion, both corners, and the upper and lower lips half-way to each corner. The other eight
add Cupid's bow (both peaks and the dip), the lower vermilion border at the midline, and four
points on the upper and lower lips close to the corners.
"""

from __future__ import annotations

import numpy as np

from lipgen.mesh.lipmesh import REGIONS, LipMesh

__all__ = [
    "MARKER_NAMES",
    "NOSE",
    "THESIS_EXTENT_UNITS",
    "lip_mesh",
    "mirror_permutation",
    "thesis_unit_mm",
]

_N_THETA, _N_BANDS, _STRIP_ROWS = 24, 6, 3  # resolution 0
_STRIP_COLS = (1, 11)  # theta indices (resolution 0) of the strip's side edges
_BAND_REGION = ("ridge", "lip", "lip", "skin", "skin", "skin")
MAX_RESOLUTION = 6

# (name, theta index at resolution 0, ring index): theta index 0 is the subject's left corner
# (+x), 6 the upper midline, 12 the right corner, 18 the lower midline.
_MARKERS = (
    ("upper_mid", 6, 2), ("lower_mid", 18, 2), ("corner_left", 0, 1), ("corner_right", 12, 1),
    ("upper_left", 3, 2), ("upper_right", 9, 2), ("lower_left", 21, 2), ("lower_right", 15, 2),
    ("bow_peak_left", 5, 3), ("bow_peak_right", 7, 3), ("bow_dip", 6, 3), ("lower_border_mid", 18, 3),
    ("upper_corner_left", 1, 2), ("upper_corner_right", 11, 2),
    ("lower_corner_left", 23, 2), ("lower_corner_right", 13, 2),
)
MARKER_NAMES: tuple[str, ...] = tuple(m[0] for m in _MARKERS)
"""The 16 marker names in thesis order; the first eight are Table 5.1's "8 points"."""

NOSE = np.array([0.0, 33.0, 15.0])
"""The nose mark (tip of the nose), mm: 13 mm above and 19 mm in front of the subnasale."""

THESIS_EXTENT_UNITS = {"x": 2.83, "y": 2.35, "z": 5.05}
"""The thesis model's extents (ch. 5: "2.35 units across, 2.83 units wide, and 5.05 units
deep"), read as width along x, height ("across", top to bottom) along y, depth along z."""

# ---- the knot rings (resolution-0 rings as closed curves in theta) ----------------------------
_ARCH_RADIUS = 35.0  # mm, curvature of the face along the dental arch
_MOUTH_HALF_WIDTH, _HALF_GAP = 25.0, 1.5  # inner contour: 50 mm corner to corner, 3 mm open
_CORNER_ROUNDING = 0.97  # towards 1: sharper mouth corners (a triangle wave in theta)
_NORMAL_ROUNDNESS = 6.0  # mm; the offset direction turns round each corner like this ellipse's normal
_BORDER = (36.0, 20.0, 40.0)  # outer skin border: half-width, height above and depth below the mouth
_SKIN_BLEND = np.array([0.3, 0.62])  # rings 4, 5 between the vermilion border and the skin border
_PROTRUDE_UP = np.array([0.0, 2.2, 3.2, 2.6, 0.4, -2.0, -4.5])  # midline depth profile, upper
_PROTRUDE_LO = np.array([0.0, 2.2, 3.0, 1.6, -2.4, -1.0, -5.0])  # midline depth profile, lower
_STRIP_RISE = np.array([0.0, 3.5, 7.0, 10.0])  # strip rows: mm up at the midline
_STRIP_BACK = np.array([0.0, 5.0, 9.0, 12.0])  # strip rows: mm back


def _side(theta, upper, lower):
    return np.where(np.sin(theta) >= 0.0, upper, lower)


def _inner_contour(theta: np.ndarray):
    """Front-view points (n, 2) of the inner contour, their normalised x in [-1, 1], and the
    offset directions (n, 2) towards the vermilion.

    The contour is a thin oval: x follows a triangle wave in ``theta`` rounded at the corners
    (``arcsin(r cos theta)``, r < 1), so nodes are evenly spaced along the lips and the corners
    are smooth on the scale of the finest elements; the parametrisation is regular (no zero
    speed), which keeps refined elements as well shaped as coarse ones. The offset direction turns
    round each corner like the normal of a 6 mm-high ellipse, so the rings fan round the corners.
    """
    xi = np.arcsin(_CORNER_ROUNDING * np.cos(theta)) / np.arcsin(_CORNER_ROUNDING)
    eta = np.sign(np.sin(theta)) * np.sqrt(np.clip(1.0 - xi**2, 0.0, None))
    p = np.stack([_MOUTH_HALF_WIDTH * xi, _HALF_GAP * eta], axis=-1)
    n = np.stack([xi / _MOUTH_HALF_WIDTH, eta / _NORMAL_ROUNDNESS], axis=-1)
    return p, xi, n / np.linalg.norm(n, axis=-1, keepdims=True)


def _lip_offsets(xi: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """(3, n) distances (mm) from the inner contour to rings 1 (end of the ridge), 2 (mid
    vermilion) and 3 (vermilion border), as functions of the contour's normalised x ``xi``.

    The upper vermilion border carries Cupid's bow; both lips thin to 5 mm round the corners,
    with equal upper and lower values there so the rings are smooth through the corners."""
    q = 1.0 - xi**2
    bow = np.exp(-(((xi**2 - 0.04) / 0.04) ** 2)) - 1.2 * np.exp(-((xi / 0.07) ** 2))
    d3 = 5.0 + q * _side(theta, 3.4 + bow, 5.0)
    d1 = 2.0 + 0.4 * q
    return np.stack([d1, 0.5 * (d1 + d3), d3])


def _depth(xy: np.ndarray, half_width: float, theta: np.ndarray, k: int) -> np.ndarray:
    """z of ring ``k``: the dental arch plus the midline profile, faded out towards the corners
    (to fourth order, so upper and lower profiles join smoothly there)."""
    x = xy[:, 0]
    fade = np.clip(1.0 - (x / half_width) ** 2, 0.0, None) ** 2
    return -(x**2) / (2.0 * _ARCH_RADIUS) + fade * _side(theta, _PROTRUDE_UP[k], _PROTRUDE_LO[k])


def _ring(theta: np.ndarray, k: int) -> np.ndarray:
    """(n, 3) points of knot ring ``k`` (0..6) at angles ``theta``."""
    p0, xi, normal = _inner_contour(theta)
    if k <= 3:
        d = 0.0 if k == 0 else _lip_offsets(xi, theta)[k - 1]
        xy = p0 + d[..., None] * normal if k else p0
        half = _MOUTH_HALF_WIDTH + (0.0 if k == 0 else float(_lip_offsets(np.ones(1), np.zeros(1))[k - 1, 0]))
    else:
        p3 = p0 + _lip_offsets(xi, theta)[2][:, None] * normal
        half3 = _MOUTH_HALF_WIDTH + float(_lip_offsets(np.ones(1), np.zeros(1))[2, 0])
        bx, bu, bl = _BORDER
        p6 = np.stack([bx * np.cos(theta), _side(theta, bu, bl) * np.sin(theta)], axis=-1)
        w = 1.0 if k == 6 else _SKIN_BLEND[k - 4]
        xy = p3 + w * (p6 - p3)
        half = half3 + w * (bx - half3)
    return np.concatenate([xy, _depth(xy, half, theta, k)[:, None]], axis=1)


def _strip_row(theta: np.ndarray, k: int) -> np.ndarray:
    """(n, 3) points of the strip's knot row ``k`` (0 is the inner contour, 3 the far end)."""
    p = _ring(theta, 0)
    taper = np.sqrt(np.clip(1.0 - (p[:, 0] / _MOUTH_HALF_WIDTH) ** 2, 0.0, None))
    p[:, 1] += _STRIP_RISE[k] * taper
    p[:, 2] -= _STRIP_BACK[k]
    return p


def _spline(knots: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Evaluate the cubic spline through ``knots`` (k, n, 3) at integer knots 0..k-1 at ``t``."""
    from scipy.interpolate import CubicSpline

    return CubicSpline(np.arange(len(knots), dtype=float), knots, axis=0)(t)


# ---- the grid -------------------------------------------------------------------------------
def _level(a: np.ndarray, b: np.ndarray, r: int) -> np.ndarray:
    """Coarsest resolution at which fine-grid node (a, b) of resolution ``r`` exists."""
    shared = np.zeros(a.shape, np.int64)
    for k in range(1, r + 1):
        step = 1 << k
        shared = np.where((a % step == 0) & (b % step == 0), k, shared)
    return r - shared


def _quads_to_triangles(p00, p10, p01, p11, V, right_half, flip):
    """Split quads (corner ids, ``p10`` one step in theta, ``p01`` one step outwards) along the
    shorter diagonal; ties go by side so that the mesh stays mirror-symmetric."""
    d_a = np.linalg.norm(V[p00] - V[p11], axis=1)
    d_b = np.linalg.norm(V[p10] - V[p01], axis=1)
    use_a = (d_a < d_b) | ((d_a == d_b) & right_half)
    tri_a = np.stack([np.stack([p00, p01, p11], 1), np.stack([p00, p11, p10], 1)], 1)
    tri_b = np.stack([np.stack([p00, p01, p10], 1), np.stack([p10, p01, p11], 1)], 1)
    tri = np.where(use_a[:, None, None], tri_a, tri_b).reshape(-1, 3)
    return tri[:, ::-1] if flip else tri


def _build(r: int):
    f = 1 << r
    n_theta, n_ring, n_rows = _N_THETA * f, _N_BANDS * f + 1, _STRIP_ROWS * f
    c0, c1 = _STRIP_COLS[0] * f, _STRIP_COLS[1] * f
    theta = 2.0 * np.pi * (np.arange(n_theta) / n_theta)

    # fine-grid nodes: ring (a, b) and strip (c, d >= 1), with the key that orders them so the
    # nodes of every coarser resolution come first, in that resolution's own order
    ra, rb = np.meshgrid(np.arange(n_theta), np.arange(n_ring), indexing="ij")
    sc, sd = np.meshgrid(np.arange(c0, c1 + 1), np.arange(1, n_rows + 1), indexing="ij")
    a = np.concatenate([ra.ravel(), sc.ravel()])
    b = np.concatenate([rb.ravel(), sd.ravel()])
    part = np.concatenate([np.zeros(ra.size, np.int64), np.ones(sc.size, np.int64)])
    lev = _level(a, b, r)
    shift = r - lev
    order = np.lexsort((a >> shift, b >> shift, part, lev))
    node_id = np.empty(len(a), np.int64)
    node_id[order] = np.arange(len(a))
    ring_id = node_id[: ra.size].reshape(n_theta, n_ring)
    strip_id = np.concatenate([ring_id[c0 : c1 + 1, :1], node_id[ra.size :].reshape(c1 - c0 + 1, n_rows)], 1)

    # positions: knot rings in theta, cubic spline across them
    V = np.empty((len(a), 3))
    rings = _spline(np.stack([_ring(theta, k) for k in range(_N_BANDS + 1)]), np.arange(n_ring) / f)
    V[ring_id] = rings.transpose(1, 0, 2)
    st = theta[c0 : c1 + 1]
    rows = _spline(np.stack([_strip_row(st, k) for k in range(_STRIP_ROWS + 1)]), np.arange(n_rows + 1) / f)
    V[strip_id[:, 1:]] = rows[1:].transpose(1, 0, 2)

    # exact mirror symmetry: copy the subject's-left half (theta in [-pi/2, pi/2]) onto the right
    mirror_ring = ring_id[(n_theta // 2 - np.arange(n_theta)) % n_theta]
    mirror_strip = strip_id[::-1]
    perm = np.empty(len(V), np.int64)
    perm[ring_id] = mirror_ring
    perm[strip_id] = mirror_strip
    left = np.zeros(len(V), bool)
    quarter = n_theta // 4
    left[ring_id[np.r_[0 : quarter + 1, n_theta - quarter + 1 : n_theta]]] = True
    left[strip_id[: (c1 - c0) // 2 + 1]] = True
    V[perm[left]] = V[left] * np.array([-1.0, 1.0, 1.0])
    V[ring_id[[quarter, 3 * quarter]], 0] = 0.0
    V[strip_id[(c1 - c0) // 2], 0] = 0.0

    # faces and regions
    nxt = (np.arange(n_theta) + 1) % n_theta
    q_right = np.cos(2.0 * np.pi * (np.arange(n_theta) + 0.5) / n_theta) > 0
    p00, p10 = ring_id[:, :-1], ring_id[nxt, :-1]
    p01, p11 = ring_id[:, 1:], ring_id[nxt, 1:]
    right = np.broadcast_to(q_right[:, None], p00.shape)
    ring_tris = _quads_to_triangles(p00.ravel(), p10.ravel(), p01.ravel(), p11.ravel(), V,
                                    right.ravel(), flip=False)
    band = np.broadcast_to(np.arange(n_ring - 1)[None, :] // f, p00.shape).ravel()
    ring_regions = np.repeat([REGIONS.index(_BAND_REGION[i]) for i in band], 2)
    q00, q10 = strip_id[:-1, :-1], strip_id[1:, :-1]
    q01, q11 = strip_id[:-1, 1:], strip_id[1:, 1:]
    s_right = np.broadcast_to(q_right[c0:c1, None], q00.shape)
    strip_tris = _quads_to_triangles(q00.ravel(), q10.ravel(), q01.ravel(), q11.ravel(), V,
                                     s_right.ravel(), flip=True)
    faces = np.concatenate([ring_tris, strip_tris])
    regions = np.concatenate([ring_regions, np.full(len(strip_tris), REGIONS.index("strip"))])
    markers = np.array([ring_id[i * f, k * f] for _, i, k in _MARKERS])
    return V, faces, regions, np.sort(strip_id[:, -1]), np.sort(ring_id[:, -1]), markers, perm


def lip_mesh(resolution: int = 0, anchor_border: bool = True) -> LipMesh:
    """The default procedural lips.

    Parameters
    ----------
    resolution : int
        0 gives 201 nodes and 348 faces (the thesis has 204 and 336); each step refines the same
        surface with 4 times the faces. Resolution 4 has 44,976 nodes. At most ``MAX_RESOLUTION``.
    anchor_border : bool
        Anchor the outer border of the skin as well as the far end of the strip (default; see
        the module docstring for why). ``False`` grounds the far end of the strip only, as the
        thesis does.

    Returns
    -------
    LipMesh
        Regions ``"ridge"``, ``"lip"``, ``"skin"`` and ``"strip"``; the anchors are the far-end
        nodes of the strip and (``anchor_border``) the outer border of the skin; 16 markers
        named by :data:`MARKER_NAMES`; the nose at :data:`NOSE`. The first ``n`` nodes of
        resolution r + 1 are the ``n`` nodes of resolution r. The geometry is described in the
        module docstring.
    """
    if isinstance(resolution, bool) or not isinstance(resolution, int | np.integer):
        raise TypeError(f"resolution must be an integer, got {resolution!r}")
    if not 0 <= resolution <= MAX_RESOLUTION:
        raise ValueError(f"resolution must be in [0, {MAX_RESOLUTION}], got {resolution} "
                         "(each step multiplies the faces by 4; resolution 4 has ~45,000 nodes)")
    V, F, R, strip_end, border, M, _ = _build(int(resolution))
    A = np.union1d(strip_end, border) if anchor_border else strip_end
    return LipMesh(V, F, R, A, M, MARKER_NAMES, NOSE, REGIONS, name=f"lips_r{int(resolution)}")


def mirror_permutation(mesh: LipMesh, atol: float = 1e-6) -> np.ndarray:
    """(n,) int: the node at each node's mirror image under x -> -x.

    ``mesh.vertices[perm] == mesh.vertices * (-1, 1, 1)``. Works for any mesh; raises
    :class:`~lipgen.errors.MeshError` if some node has no mirror image within ``atol`` mm.
    """
    from scipy.spatial import cKDTree

    from lipgen.errors import MeshError

    V = mesh.vertices
    dist, perm = cKDTree(V).query(V * np.array([-1.0, 1.0, 1.0]))
    bad = dist > atol
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise MeshError(f"mesh {mesh.name!r} is not symmetric under x -> -x: {int(bad.sum())} "
                        f"node(s) have no mirror image within {atol} mm, e.g. node {i} at "
                        f"{V[i].round(4).tolist()} (nearest mirror {dist[i]:.3g} mm away)")
    return perm.astype(np.int64)


def thesis_unit_mm(mesh: LipMesh | None = None) -> float:
    """Millimetres per unit of the thesis's normalised model coordinates.

    The thesis gives its model as 2.83 units wide; the width (the x extent of the whole mesh)
    is the one extent that means the same thing in both models, so the scale is
    ``x extent / 2.83``. For the default lips (72 mm wide, any resolution) that is 25.44 mm,
    and their 60 mm height is then 2.36 units, matching the thesis's 2.35 "across". The
    thesis's 5.05 units of depth (128 mm) cannot be matched: its strip reached much further
    back than anatomy suggests; depth is therefore not used. Divide lengths in mm by this to get
    thesis units (and squared errors by its square).

    Parameters
    ----------
    mesh : LipMesh, optional
        The mesh whose width defines the scale; the default lips if omitted.
    """
    V = lip_mesh(0).vertices if mesh is None else mesh.vertices
    return float(np.ptp(V[:, 0])) / THESIS_EXTENT_UNITS["x"]
