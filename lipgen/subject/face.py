"""What the camera sees of the subject: the lips dressed as a face region, with ink dots.

The lip mesh alone looks odd in a picture, so :class:`FaceModel` adds cheap surroundings:

- a *face proxy*: rings of skin continuing the lip mesh's outer border out to an oval the
  size of a lower face, shaped like a face (flat in front, wrapping round at the cheeks,
  receding under the chin and at the eyes). Its first ring *is* the lip border, so the seam is
  watertight, and the rings near it follow the border's motion (the skin stretches);
- a *nose*: an ellipsoid whose tip is exactly the mesh's nose point;
- a *mouth cavity*: a dark bowl behind the lips, seen through the open mouth.

Sixteen ink dots sit on the lip markers and one on the nose (see :mod:`lipgen.subject.decal`). All of
it is rigid with the head pose except the lips and the proxy's stretch. Colours: skin, the
vermilion (regions ``lip`` and ``ridge``) and mucosa (``strip``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lipgen._validate import as_float_array
from lipgen.mesh.lipmesh import LipMesh
from lipgen.rig.scene import Light, Material, MeshItem, Scene, vertex_normals
from lipgen.subject.decal import make_decal, make_decal_at, place_decal

__all__ = ["FaceLook", "FaceModel", "LABELS", "DOT_LABEL0", "boundary_loops"]

LABELS = {0: "background", 1: "skin", 2: "vermilion", 3: "mouth"}
"""Label ids of label renders; ink dots are ``10 + k`` for marker k and ``10 + n_markers`` for the nose."""

DOT_LABEL0 = 10
"""Label id of marker 0's ink dot in label renders (marker k is ``DOT_LABEL0 + k``)."""
# face profile: depth of the face surface at the midline against height (mm, model frame)
_PROFILE_Y = np.array([-95, -80, -68, -50, -30, 0, 20, 35, 55, 75, 100, 130.0])
_PROFILE_Z = np.array([-60, -30, -14, -10, -9, -4, -5, -8, -24, -26, -20, -30.0])
_CHEEK_RADIUS = 80.0  # mm, curvature of the face across x
_OUTER = np.array([78.0, 110.0])  # semi-axes of the proxy's outer oval (x, y)
_OUTER_Y0 = 15.0
_RINGS, _FADE = 10, 0.5


@dataclass(frozen=True)
class FaceLook:
    """Colours (sRGB) and sizes of the rendered subject."""

    skin: tuple[float, float, float] = (0.86, 0.66, 0.55)
    vermilion: tuple[float, float, float] = (0.72, 0.32, 0.33)
    mucosa: tuple[float, float, float] = (0.60, 0.24, 0.26)
    cavity: tuple[float, float, float] = (0.20, 0.06, 0.07)
    ink: tuple[float, float, float] = (0.04, 0.04, 0.05)
    background: tuple[float, float, float] = (0.40, 0.45, 0.50)
    dot_diameter: float = 2.0
    """Ink dot diameter, mm."""
    dot_lift: float = 0.05
    """Height of the dots above the skin, mm (keeps them in front in the depth test)."""
    surroundings: bool = True
    """Draw the face proxy, the nose and the mouth cavity (otherwise the lips alone)."""
    texture: float = 0.0
    """Strength of the procedural skin and lip textures (:mod:`lipgen.subject.skin`), 0 for none;
    with textures the skin tone is drawn per subject too."""
    texture_seed: int = 0
    """Seed of the subject's textures and skin tone."""

    def __post_init__(self) -> None:
        if not 0.2 <= self.dot_diameter <= 20:
            raise ValueError(f"dot_diameter must be in [0.2, 20] mm, got {self.dot_diameter}")


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Closed boundary loops of a triangle mesh, each an ordered array of vertex indices.

    Boundary edges are those used by one face; each loop follows the faces' orientation.
    """
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    key = np.sort(e, axis=1)
    _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    border = e[counts[inv.ravel()] == 1]
    nxt = dict(zip(border[:, 0].tolist(), border[:, 1].tolist(), strict=True))
    loops, seen = [], set()
    for start in nxt:
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen:
            seen.add(v)
            loop.append(v)
            v = nxt.get(v)
            if v is None:
                raise ValueError("the mesh boundary is not a set of closed loops (non-manifold border)")
        loops.append(np.array(loop, np.int64))
    return loops


def _face_depth(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Depth of the proxy face surface at (x, y): midline profile, wrapped round the cheeks."""
    z0 = np.interp(y, _PROFILE_Y, _PROFILE_Z)
    return z0 - _CHEEK_RADIUS + np.sqrt(np.clip(_CHEEK_RADIUS**2 - x**2, 0.0, None))


def _ellipsoid(center, axes, n_rings: int = 12, n_sectors: int = 24, cap: float = np.pi):
    """Vertices, faces and normals of an ellipsoid whose pole ``center + a0`` is vertex 0.

    ``axes`` (3, 3) rows are the semi-axis vectors: the first points to the pole.
    """
    a0, a1, a2 = axes
    theta = cap * np.arange(1, n_rings + 1) / n_rings
    phi = 2 * np.pi * np.arange(n_sectors) / n_sectors
    ct, st = np.cos(theta)[:, None, None], np.sin(theta)[:, None, None]
    ring = ct * a0 + st * (np.cos(phi)[None, :, None] * a1 + np.sin(phi)[None, :, None] * a2)
    V = np.vstack([center + a0, center + ring.reshape(-1, 3)])
    s = np.arange(n_sectors)
    s1 = (s + 1) % n_sectors
    F = [np.stack([np.zeros(n_sectors, np.int64), 1 + s1, 1 + s], 1)]
    for k in range(n_rings - 1):
        a, b = 1 + k * n_sectors + s, 1 + k * n_sectors + s1
        F += [np.stack([a, b + n_sectors, a + n_sectors], 1), np.stack([a, b, b + n_sectors], 1)]
    F = np.vstack(F)
    M = np.linalg.inv(np.stack([a0, a1, a2], 1))
    N = (V - center) @ M.T @ M  # gradient of the quadric: the outward normal
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    tri = V[F]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    if np.sum(fn * N[F].sum(axis=1)) < 0:  # wind the faces counter-clockwise seen from outside
        F = F[:, ::-1]
    return V, F, N


class FaceModel:
    """The rendered subject around a :class:`~lipgen.mesh.LipMesh`, built once at rest.

    Parameters
    ----------
    mesh : LipMesh
        The lips (model frame, mm); any mesh with one outer boundary loop around the mouth.
    look : FaceLook
        Colours, dot size, whether to draw the surroundings.
    dots : lipgen.subject.inkdots.SurfaceDots, optional
        The ink dots as surface points of ``mesh`` (one per marker, in marker order); by default
        each dot sits on its marker's node.
    """

    def __init__(self, mesh: LipMesh, look: FaceLook = FaceLook(), dots=None) -> None:
        self.mesh, self.look, self.dots = mesh, look, dots
        if dots is not None and len(dots.face) != len(mesh.markers):
            raise ValueError(f"dots must give one surface point per marker ({len(mesh.markers)}), "
                             f"got {len(dots.face)}")
        vermilion = [mesh.region_names.index(r) for r in ("lip", "ridge") if r in mesh.region_names]
        mouth = [mesh.region_names.index(r) for r in ("strip",) if r in mesh.region_names]
        lip_mat = np.where(np.isin(mesh.regions, vermilion), 1, np.where(np.isin(mesh.regions, mouth), 2, 0))
        skin_tex = lip_tex = None
        skin = look.skin
        if look.texture > 0:
            from lipgen.subject import skin as proc

            rng = np.random.default_rng([look.texture_seed, 7])
            skin = proc.skin_tone(rng)
            skin_tex, lip_tex = proc.skin_texture(rng, look.texture), proc.lip_texture(rng, look.texture)
        # wet vermilion: smoother (more specular) than the skin when textured
        self.materials = (Material("skin", skin, 0.65, label=1, texture=skin_tex),
                          Material("vermilion", look.vermilion, 0.4 if lip_tex is None else 0.3, label=2,
                                   texture=lip_tex),
                          Material("mucosa", look.mucosa, 0.4, double_sided=True, label=3))
        self.ink = tuple(Material(f"ink_{k}", look.ink, 0.8, label=DOT_LABEL0 + k)
                         for k in range(len(mesh.markers) + 1))
        self.cavity_material = Material("cavity", look.cavity, 0.9, double_sided=True, label=3)
        if look.surroundings:
            self._build_proxy(mesh)
        else:
            self.loop = np.zeros(0, np.int64)
            self.proxy_rest = np.zeros((0, 3))
            self.proxy_faces = np.zeros((0, 3), np.int64)
            self.fade = np.zeros(0)
        self.faces = np.vstack([mesh.faces, self.proxy_faces])
        self.face_material = np.concatenate([lip_mat, np.zeros(len(self.proxy_faces), np.int64)])
        self._build_nose(mesh.nose)
        V0 = self._face_vertices(mesh.vertices)
        N0 = vertex_normals(V0, self.faces)
        self.uv = self.nose_uv = None
        if look.texture > 0:
            from lipgen.subject.skin import uv_of

            self.uv, self.nose_uv = uv_of(V0), uv_of(self.nose_vertices)
        radius = look.dot_diameter / 2
        if dots is None:
            self.marker_decals = [make_decal(V0, self.faces, N0, int(i), radius) for i in mesh.markers]
        else:
            self.marker_decals = [make_decal_at(V0, self.faces, N0, int(f), b, radius)
                                  for f, b in zip(dots.face, dots.bary, strict=True)]
        self.nose_decal = make_decal(self.nose_vertices, self.nose_faces, self.nose_normals, 0, radius)

    # ---- construction ---------------------------------------------------------------------
    def _build_proxy(self, mesh: LipMesh) -> None:
        loops = boundary_loops(mesh.faces)
        if not loops:
            raise ValueError(f"mesh {mesh.name!r} has no boundary; the face proxy needs its outer border")
        V = mesh.vertices

        def area(loop):
            x, y = V[loop, 0], V[loop, 1]
            return 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)

        loop = max(loops, key=lambda lp: abs(area(lp)))
        if area(loop) < 0:
            loop = loop[::-1]  # counter-clockwise seen from the front (+z)
        b = V[loop]
        # rays from the border's centre out to the oval (centre (0, _OUTER_Y0), semi-axes scale)
        c = b[:, :2].mean(axis=0)
        d = b[:, :2] - c
        if (np.linalg.norm(d, axis=1) == 0).any():
            raise ValueError("the lip mesh border passes through its own centre; cannot build a face proxy")
        scale = np.maximum(_OUTER, 1.6 * np.abs(b[:, :2] - [0.0, _OUTER_Y0]).max(axis=0))
        q = (c - [0.0, _OUTER_Y0]) / scale
        dd = d / scale
        qa, qb, qc = np.sum(dd * dd, axis=1), 2 * dd @ q, q @ q - 1.0
        lam = (-qb + np.sqrt(qb * qb - 4 * qa * qc)) / (2 * qa)
        outer = c + lam[:, None] * d
        s = (np.arange(1, _RINGS + 1) / _RINGS) ** 1.6
        xy = b[None, :, :2] + s[:, None, None] * (outer - b[:, :2])[None]
        resid = b[:, 2] - _face_depth(b[:, 0], b[:, 1])
        z = _face_depth(xy[..., 0], xy[..., 1]) + resid[None] * ((1 - s) ** 3)[:, None]
        self.loop = loop
        self.proxy_rest = np.concatenate([xy, z[..., None]], axis=-1).reshape(-1, 3)
        self.fade = np.clip(1 - s / _FADE, 0, None) ** 2
        k, n = len(loop), mesh.n_nodes
        ids = np.vstack([loop[None], n + np.arange(_RINGS * k).reshape(_RINGS, k)])
        i = np.arange(k)
        i1 = (i + 1) % k
        a, b_, c_, d_ = ids[:-1][:, i], ids[:-1][:, i1], ids[1:][:, i], ids[1:][:, i1]
        self.proxy_faces = np.concatenate([np.stack([a, d_, b_], -1).reshape(-1, 3),
                                           np.stack([a, c_, d_], -1).reshape(-1, 3)])

    def _build_nose(self, nose: np.ndarray) -> None:
        d = np.array([0.0, -0.25, 1.0])
        d /= np.linalg.norm(d)
        dorsum = np.array([0.0, 0.94, -0.34])  # the bridge runs up and back into the face
        axes = np.stack([13.0 * d, 22.0 * dorsum, 11.0 * np.array([1.0, 0, 0])])
        self.nose_vertices, self.nose_faces, self.nose_normals = _ellipsoid(nose - 13.0 * d, axes)
        cav = np.stack([[0, 0, -20.0], [0, 24.0, 0], [26.0, 0, 0]])
        cv, cf, cn = _ellipsoid(np.array([0.0, -8.0, -18.0]), cav, 8, 24, np.pi / 2)
        self.cavity_vertices, self.cavity_faces, self.cavity_normals = cv, cf[:, ::-1], -cn

    # ---- per frame ------------------------------------------------------------------------
    def _face_vertices(self, lips: np.ndarray) -> np.ndarray:
        if not len(self.proxy_rest):
            return lips
        moved = lips[self.loop] - self.mesh.vertices[self.loop]
        k = len(self.loop)
        proxy = self.proxy_rest.reshape(_RINGS, k, 3) + self.fade[:, None, None] * moved[None]
        return np.vstack([lips, proxy.reshape(-1, 3)])

    def surfaces(self, vertices, pose=None) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """World geometry of every surface: name -> (vertices, faces, normals).

        Parameters
        ----------
        vertices : (n, 3) float
            Lip vertex positions in the model frame, mm.
        pose : (4, 4) float, optional
            Model-to-world transform (head pose); identity by default.
        """
        R, t = _pose(pose)
        V = as_float_array(vertices, "vertices", (self.mesh.n_nodes, 3))
        Vf = self._face_vertices(V) @ R.T + t
        out = {"face": (Vf, self.faces, vertex_normals(Vf, self.faces))}
        if self.look.surroundings:
            out["nose"] = (self.nose_vertices @ R.T + t, self.nose_faces, self.nose_normals @ R.T)
            out["cavity"] = (self.cavity_vertices @ R.T + t, self.cavity_faces, self.cavity_normals @ R.T)
        return out

    def marks(self, vertices, pose=None) -> tuple[np.ndarray, np.ndarray]:
        """World positions and unit surface normals of the markers then the nose: ``(k + 1, 3)`` each."""
        R, t = _pose(pose)
        V = as_float_array(vertices, "vertices", (self.mesh.n_nodes, 3))
        Vf = self._face_vertices(V)
        Nv = vertex_normals(Vf, self.faces)
        if self.dots is None:
            N, M = Nv[self.mesh.markers], V[self.mesh.markers]
        else:  # the dots' own surface points and interpolated normals
            idx = self.mesh.faces[self.dots.face]
            M = np.einsum("kj,kjd->kd", self.dots.bary, V[idx])
            N = np.einsum("kj,kjd->kd", self.dots.bary, Nv[idx])
            N /= np.linalg.norm(N, axis=1, keepdims=True)
        P = np.vstack([M, self.mesh.nose])
        return P @ R.T + t, np.vstack([N, self.nose_normals[:1]]) @ R.T

    def dot_rims(self, surfaces: dict) -> list[np.ndarray]:
        """World rim points of each dot (markers then nose), from :meth:`surfaces` output."""
        Vf, F, N = surfaces["face"]
        rims = [place_decal(d, Vf, F, N, 0.0)[d.rim] for d in self.marker_decals]
        if "nose" in surfaces:
            Vn, Fn, Nn = surfaces["nose"]
            rims.append(place_decal(self.nose_decal, Vn, Fn, Nn, 0.0)[self.nose_decal.rim])
        return rims

    def scene(self, vertices, pose=None, lights: tuple[Light, ...] | None = None) -> Scene:
        """The renderer-independent :class:`~lipgen.rig.scene.Scene` of one frame."""
        surf = self.surfaces(vertices, pose)
        Vf, F, N = surf["face"]
        items = [MeshItem("face", Vf, F, self.materials, self.face_material, N, self.uv)]
        dots = [(d, Vf, F, N) for d in self.marker_decals]
        if self.look.surroundings:
            Vn, Fn, Nn = surf["nose"]
            items.append(MeshItem("nose", Vn, Fn, self.materials[:1], None, Nn, self.nose_uv))
            dots.append((self.nose_decal, Vn, Fn, Nn))
            Vc, Fc, Nc = surf["cavity"]
            items.append(MeshItem("cavity", Vc, Fc, (self.cavity_material,), None, Nc))
        items.append(_dots_item(dots, self.ink, self.look.dot_lift))
        labels = dict(LABELS)
        labels.update({DOT_LABEL0 + k: f"dot:{name}" for k, name in enumerate(self.mesh.marker_names)})
        labels[DOT_LABEL0 + len(self.mesh.markers)] = "dot:nose"
        return Scene(tuple(items), default_lights() if lights is None else lights, (0.22, 0.2, 0.2),
                     self.look.background, labels)

    def occluders(self, surfaces: dict) -> np.ndarray:
        """(T, 3, 3) world triangles that can hide a dot (all surfaces)."""
        return np.vstack([V[F] for V, F, _ in surfaces.values()])


def _dots_item(dots: list, ink: tuple[Material, ...], lift: float) -> MeshItem:
    """All ink dots as one mesh (one draw call), dot k with material ``ink[k]``."""
    P, Fs, Ns, mats, offset = [], [], [], [], 0
    for k, (decal, V, F, N) in enumerate(dots):
        P.append(place_decal(decal, V, F, N, lift))
        nrm = np.einsum("kj,kjd->kd", decal.bary, N[F[decal.face]])
        Ns.append(nrm / np.linalg.norm(nrm, axis=1, keepdims=True))
        Fs.append(decal.faces + offset)
        mats.append(np.full(len(decal.faces), k))
        offset += len(P[-1])
    return MeshItem("dots", np.vstack(P), np.vstack(Fs), ink[:len(dots)], np.concatenate(mats), np.vstack(Ns))


def _pose(pose) -> tuple[np.ndarray, np.ndarray]:
    if pose is None:
        return np.eye(3), np.zeros(3)
    T = as_float_array(pose, "pose", (4, 4))
    R = T[:3, :3]
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
        raise ValueError("pose must be a rigid (4, 4) model-to-world transform with a proper rotation")
    return R, T[:3, 3]


def default_lights() -> tuple[Light, ...]:
    """A key light from above the camera side, a dimmer fill from the mirror side, and a top light."""
    return (Light("directional", (1.0, 0.97, 0.92), 3.2, direction=(-0.3, -0.45, -1.0)),
            Light("directional", (0.9, 0.95, 1.0), 1.4, direction=(0.7, -0.1, -0.8)),
            Light("directional", (1.0, 1.0, 1.0), 0.8, direction=(0.0, -1.0, -0.2)))
