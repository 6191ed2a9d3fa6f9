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

A :class:`FaceLook` can ask for more of a real recording: a head (``head``: cheeks, chin,
nasolabial folds and a nose with nostrils, :mod:`lipgen.subject.head`), the inside of the mouth
(``mouth``: teeth, tongue, a deep cavity, :mod:`lipgen.subject.mouth`) and ink that looks like
ink (``dot_irregularity``, ``dot_smudge``: :mod:`lipgen.subject.ink`). All of it is drawn from the
look's seed and listed by :meth:`FaceModel.record`; off by default, so the plain face draws as it
always did.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from lipgen._validate import as_float_array
from lipgen.mesh.lipmesh import LipMesh
from lipgen.rig.scene import Light, Material, MeshItem, Scene, vertex_normals
from lipgen.subject.decal import _dots_items, make_decal, make_decal_at, place_decal
from lipgen.subject.head import (
    HEAD_MESH,
    PROXY,
    build_proxy,
    ellipsoid,
    face_depth,
    head_shape,
    nose_mesh,
)

__all__ = ["FaceLook", "FaceModel", "LABELS", "DOT_LABEL0", "boundary_loops", "look_record"]

LABELS = {0: "background", 1: "skin", 2: "vermilion", 3: "mouth", 4: "teeth", 5: "tongue"}
"""Label ids of label renders; ink dots are ``10 + k`` for marker k and ``10 + n_markers`` for the nose."""

DOT_LABEL0 = 10
"""Label id of marker 0's ink dot in label renders (marker k is ``DOT_LABEL0 + k``)."""
_OUTER = np.array([78.0, 110.0])  # semi-axes of the proxy's outer oval (x, y)
_OUTER_Y0 = 15.0
_HEAD_STREAM, _INK_STREAM = 8, 9


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
    """Seed of the subject's textures, skin tone, head shape and ink."""
    head: bool = False
    """A head round the lips: cheeks, chin, nasolabial folds, a nose with nostrils."""
    head_mesh: tuple[int, int, int, int] = HEAD_MESH
    """Tessellation of the head: the face proxy's rings and border subdivision, the nose's rings
    and sectors (:data:`lipgen.subject.head.HEAD_MESH`)."""
    mouth: bool = False
    """Teeth, tongue and a deep oral cavity (else a shallow dark bowl)."""
    dot_irregularity: float = 0.0
    """0..1: how irregular the ink dots are (edges, sizes); 0 for perfect discs."""
    dot_smudge: float = 0.0
    """0..1: opacity of the smudge halo round each dot at the end of the clip."""

    def __post_init__(self) -> None:
        if not 0.2 <= self.dot_diameter <= 20:
            raise ValueError(f"dot_diameter must be in [0.2, 20] mm, got {self.dot_diameter}")
        for name in ("dot_irregularity", "dot_smudge"):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(f"FaceLook.{name} must be in [0, 1], got {getattr(self, name)!r}")


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


@functools.lru_cache(maxsize=4)
def _subject_textures(texture_seed, strength: float) -> tuple:
    """(skin tone, skin texture, lip texture) of a subject, made once per process for the last 4
    subjects: the same seed gives the same bytes, and a dataset's every worker, a campaign's
    datasets of one subject and a test session's renderers of the default subject made them anew
    (0.7 s of CPU each). The arrays are read-only, shared by the face models of that subject."""
    from lipgen.subject import skin as proc

    rng = np.random.default_rng([texture_seed, 7])
    tone = proc.skin_tone(rng)
    skin_tex, lip_tex = proc.skin_texture(rng, strength), proc.lip_texture(rng, strength)
    skin_tex.flags.writeable = lip_tex.flags.writeable = False
    return tone, skin_tex, lip_tex


class FaceModel:
    """The rendered subject around a :class:`~lipgen.mesh.LipMesh`, built once at rest.

    Parameters
    ----------
    mesh : LipMesh
        The lips (model frame, mm); any mesh with one outer boundary loop around the mouth.
    look : FaceLook
        Colours, dot size, whether to draw the surroundings, head, mouth and ink.
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
            skin, skin_tex, lip_tex = _subject_textures(look.texture_seed, float(look.texture))
        # wet vermilion: smoother (more specular) than the skin when textured
        self.materials = (Material("skin", skin, 0.65, label=1, texture=skin_tex),
                          Material("vermilion", look.vermilion, 0.4 if lip_tex is None else 0.3, label=2,
                                   texture=lip_tex),
                          Material("mucosa", look.mucosa, 0.4, double_sided=True, label=3))
        self.ink = tuple(Material(f"ink_{k}", look.ink, 0.8, label=DOT_LABEL0 + k)
                         for k in range(len(mesh.markers) + 1))
        self.cavity_material = Material("cavity", look.cavity, 0.9, double_sided=True, label=3)
        self.head = head_shape([look.texture_seed, _HEAD_STREAM]) if look.head and look.surroundings else None
        self.interior = None
        if look.mouth and look.surroundings:
            from lipgen.subject.mouth import MouthInterior

            self.interior = MouthInterior(mesh)
            self.interior_materials = {
                "upper_teeth": (Material("teeth", (0.93, 0.9, 0.82), 0.35, label=4),),
                "lower_teeth": (Material("teeth", (0.93, 0.9, 0.82), 0.35, label=4),),
                "tongue": (Material("tongue", (0.72, 0.36, 0.38), 0.45, label=5),),
                "cavity": (self.cavity_material, Material("throat", (0.05, 0.01, 0.015), 1.0, True, label=3))}
        self.style = None
        if look.dot_irregularity > 0 or look.dot_smudge > 0:
            from lipgen.subject.ink import ink_style

            self.style = ink_style([look.texture_seed, _INK_STREAM], len(mesh.markers) + 1,
                                   look.dot_irregularity, look.dot_smudge)
        if look.surroundings:
            self._build_proxy(mesh)
        else:
            self.loop = np.zeros(0, np.int64)
            self.proxy_rest = np.zeros((0, 3))
            self.proxy_faces = np.zeros((0, 3), np.int64)
            self.fade = np.zeros(0)
            self._col = np.zeros(0, np.int64)
        self.faces = np.vstack([mesh.faces, self.proxy_faces])
        self.face_material = np.concatenate([lip_mat, np.zeros(len(self.proxy_faces), np.int64)])
        self._build_nose(mesh.nose)
        V0 = self._face_vertices(mesh.vertices)
        N0 = vertex_normals(V0, self.faces)
        self.uv = self.nose_uv = None
        if look.texture > 0:
            from lipgen.subject.skin import uv_of

            self.uv, self.nose_uv = uv_of(V0), uv_of(self.nose_vertices)
        self._lay_dots(V0, N0)

    # ---- construction ---------------------------------------------------------------------
    def _lay_dots(self, V0: np.ndarray, N0: np.ndarray) -> None:
        radius, st, mesh = self.look.dot_diameter / 2, self.style, self.mesh
        kw = [{} if st is None else {"sectors": 24, "outline": st.outline(k), "halo": st.halo}
              for k in range(len(mesh.markers) + 1)]
        if self.dots is None:
            self.marker_decals = [make_decal(V0, self.faces, N0, int(i), radius, **kw[k])
                                  for k, i in enumerate(mesh.markers)]
        else:
            pts = zip(self.dots.face, self.dots.bary, strict=True)
            self.marker_decals = [make_decal_at(V0, self.faces, N0, int(f), b, radius, **kw[k])
                                  for k, (f, b) in enumerate(pts)]
        self.nose_decal = make_decal(self.nose_vertices, self.nose_faces, self.nose_normals, 0, radius,
                                     **kw[-1])

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
        rings, subdiv = PROXY["plain"] if self.head is None else self.look.head_mesh[:2]
        head = self.head
        p = build_proxy(V[loop], _OUTER, _OUTER_Y0, rings, subdiv, lambda x, y: face_depth(x, y, head))
        self.loop, self.proxy_rest, self.fade, self._col = loop, p["rest"], p["fade"], p["col"]
        self._weights = None if subdiv == 1 else p["weights"]
        n = mesh.n_nodes
        ids = np.where(p["ids"] < 0, loop[-1 - np.minimum(p["ids"], -1)], n + p["ids"])
        K = ids.shape[1]
        i = np.arange(K)
        i1 = (i + 1) % K
        a, b_, c_, d_ = ids[:-1][:, i], ids[:-1][:, i1], ids[1:][:, i], ids[1:][:, i1]
        self.proxy_faces = np.concatenate([np.stack([a, d_, b_], -1).reshape(-1, 3),
                                           np.stack([a, c_, d_], -1).reshape(-1, 3)])

    def _build_nose(self, nose: np.ndarray) -> None:
        self.nose_material = np.zeros(0, np.int64)
        if self.head is None:
            d = np.array([0.0, -0.25, 1.0])
            d /= np.linalg.norm(d)
            dorsum = np.array([0.0, 0.94, -0.34])  # the bridge runs up and back into the face
            axes = np.stack([13.0 * d, 22.0 * dorsum, 11.0 * np.array([1.0, 0, 0])])
            self.nose_vertices, self.nose_faces, self.nose_normals = ellipsoid(nose - 13.0 * d, axes)
        else:
            nr, ns = self.look.head_mesh[2:]
            self.nose_vertices, self.nose_faces, nostril = nose_mesh(nose, self.head, nr, ns)
            self.nose_normals = vertex_normals(self.nose_vertices, self.nose_faces)
            self.nose_material = nostril.astype(np.int64)
            self.nostril_material = Material("nostril", (0.12, 0.05, 0.05), 0.9, label=3)
        cav = np.stack([[0, 0, -20.0], [0, 24.0, 0], [26.0, 0, 0]])
        cv, cf, cn = ellipsoid(np.array([0.0, -8.0, -18.0]), cav, 8, 24, np.pi / 2)
        self.cavity_vertices, self.cavity_faces, self.cavity_normals = cv, cf[:, ::-1], -cn

    # ---- per frame ------------------------------------------------------------------------
    def _face_vertices(self, lips: np.ndarray) -> np.ndarray:
        if not len(self.proxy_rest):
            return lips
        moved = lips[self.loop] - self.mesh.vertices[self.loop]
        if self._weights is not None:
            moved = self._weights @ moved
        proxy = self.proxy_rest + self.fade[:, None] * moved[self._col]
        return np.vstack([lips, proxy])

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
            if self.interior is None:
                out["cavity"] = (self.cavity_vertices @ R.T + t, self.cavity_faces, self.cavity_normals @ R.T)
            else:
                for name, (Vi, Fi, _) in self.interior.surfaces(V).items():
                    Vw = Vi @ R.T + t
                    out[name] = (Vw, Fi, vertex_normals(Vw, Fi))
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

    def scene(self, vertices, pose=None, lights: tuple[Light, ...] | None = None, age: float = 0.0) -> Scene:
        """The renderer-independent :class:`~lipgen.rig.scene.Scene` of one frame.

        ``age`` (0..1) is how far through the clip the frame is (the ink's smudging).
        """
        surf = self.surfaces(vertices, pose)
        Vf, F, N = surf["face"]
        items = [MeshItem("face", Vf, F, self.materials, self.face_material, N, self.uv)]
        dots = [(d, Vf, F, N) for d in self.marker_decals]
        if self.look.surroundings:
            Vn, Fn, Nn = surf["nose"]
            if self.head is None:
                items.append(MeshItem("nose", Vn, Fn, self.materials[:1], None, Nn, self.nose_uv))
            else:
                items.append(MeshItem("nose", Vn, Fn, (self.materials[0], self.nostril_material),
                                      self.nose_material, Nn, self.nose_uv))
            dots.append((self.nose_decal, Vn, Fn, Nn))
            if self.interior is None:
                Vc, Fc, Nc = surf["cavity"]
                items.append(MeshItem("cavity", Vc, Fc, (self.cavity_material,), None, Nc))
            else:
                for name, (_, _, fp) in self.interior.parts.items():
                    Vi, Fi, Ni = surf[name]
                    items.append(MeshItem(name, Vi, Fi, self.interior_materials[name], fp, Ni))
        items += _dots_items(dots, self.ink, self.look.dot_lift, self.style, age)
        labels = dict(LABELS)
        labels.update({DOT_LABEL0 + k: f"dot:{name}" for k, name in enumerate(self.mesh.marker_names)})
        labels[DOT_LABEL0 + len(self.mesh.markers)] = "dot:nose"
        return Scene(tuple(items), default_lights() if lights is None else lights, (0.22, 0.2, 0.2),
                     self.look.background, labels)

    def occluders(self, surfaces: dict) -> np.ndarray:
        """(T, 3, 3) world triangles that can hide a dot (all surfaces)."""
        return np.vstack([V[F] for V, F, _ in surfaces.values()])

    def record(self) -> dict:
        """What was drawn beyond the plain face, as a JSON-ready dict (see :func:`look_record`)."""
        return look_record(self.look, len(self.mesh.markers) + 1)


def look_record(look: FaceLook, n_dots: int) -> dict:
    """What a :class:`FaceModel` with ``look`` and ``n_dots`` dots draws beyond the plain face: the
    head shape, the mouth's parts and the ink style (each ``None`` when off), as a JSON-ready dict
    (for the manifest); computed from the look alone, without building the face."""
    on = look.surroundings
    style = None
    if look.dot_irregularity > 0 or look.dot_smudge > 0:
        from lipgen.subject.ink import ink_style

        style = ink_style([look.texture_seed, _INK_STREAM], n_dots, look.dot_irregularity, look.dot_smudge)
    return {"head": head_shape([look.texture_seed, _HEAD_STREAM]).to_dict() if look.head and on else None,
            "mouth": ["cavity", "lower_teeth", "tongue", "upper_teeth"] if look.mouth and on else None,
            "ink": None if style is None else style.to_dict(), "seed": look.texture_seed,
            "units": "mm; ink scale and edge amplitudes relative to the dot's radius"}


def _pose(pose) -> tuple[np.ndarray, np.ndarray]:
    if pose is None:
        return np.eye(3), np.zeros(3)
    T = as_float_array(pose, "pose", (4, 4))
    R = T[:3, :3]
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
        raise ValueError("pose must be a rigid (4, 4) model-to-world transform with a proper rotation")
    return R, T[:3, 3]


def default_lights() -> tuple[Light, ...]:
    """A key light from above the camera side (the one that casts shadows), a dimmer fill from the
    mirror side, and a top light."""
    return (Light("directional", (1.0, 0.97, 0.92), 3.2, direction=(-0.3, -0.45, -1.0)),
            Light("directional", (0.9, 0.95, 1.0), 1.4, direction=(0.7, -0.1, -0.8), shadows=False),
            Light("directional", (1.0, 1.0, 1.0), 0.8, direction=(0.0, -1.0, -0.2), shadows=False))
