"""A renderer-independent description of what to draw (in the spirit of Kubric's scene objects).

Plain frozen records of meshes, materials and lights in world coordinates (mm). Nothing here
knows about OpenGL; :mod:`lipgen.rig.render` turns a :class:`Scene` into pyrender objects, and the
cameras come from the :class:`~lipgen.rig.camera.MirrorRig`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lipgen._validate import as_float_array, as_index_array

__all__ = ["Material", "MeshItem", "Light", "Scene", "srgb_to_linear", "vertex_normals"]


def srgb_to_linear(c) -> np.ndarray:
    """sRGB colour components in [0, 1] to linear light (the renderers shade in linear light)."""
    c = np.asarray(c, float)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(n, 3) unit area-weighted vertex normals (zero for vertices in no face).

    Each vertex sums its faces' cross products in the order of ``np.add.at`` over the faces'
    first, second, then third corners (``np.bincount`` adds its weights in that same order, at a
    quarter of the CPU): the same bits as that sum.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    """
    vertices = np.asarray(vertices)
    faces = np.asarray(faces)
    if vertices.dtype != np.float64:  # bincount adds in float64: the other types keep np.add.at
        tri = vertices[faces]
        nrm3 = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        out = np.zeros_like(vertices)
        for k in range(3):
            np.add.at(out, faces[:, k], nrm3)
        length = np.linalg.norm(out, axis=1, keepdims=True)
        return np.divide(out, length, out=np.zeros_like(out), where=length > 0)
    Vt = np.ascontiguousarray(vertices.T)
    a, b, c = (Vt[:, faces[:, k]] for k in range(3))
    e1, e2 = b - a, c - a  # np.cross's products and differences, per component
    nrm = (e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0])
    corners = faces.T.ravel()
    out = np.stack([np.bincount(corners, np.concatenate([x, x, x]), len(vertices)) for x in nrm], axis=1)
    length = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, length, out=np.zeros_like(out), where=length > 0)


@dataclass(frozen=True)
class Material:
    """A physically based surface.

    Parameters
    ----------
    name : str
    color : (3,) float
        Base colour, sRGB in [0, 1].
    roughness : float
        0 mirror-like to 1 matte.
    double_sided : bool
        Draw back faces too (open shells seen from inside).
    label : int
        Class id written by label renders (0 is reserved for the background).
    texture : (h, w, 3) uint8, optional
        sRGB image multiplied with ``color``, mapped by the mesh item's ``uv`` (read-only; compared
        by identity, so share one array between frames).
    opacity : float
        Coverage in (0, 1]: below 1 the surface is blended over what lies behind it (faint ink).
    """

    name: str
    color: tuple[float, float, float]
    roughness: float = 0.6
    double_sided: bool = False
    label: int = 1
    texture: np.ndarray | None = field(default=None, compare=False, repr=False)
    opacity: float = 1.0

    def __post_init__(self) -> None:
        c = as_float_array(self.color, f"material {self.name!r} color", (3,))
        if (c < 0).any() or (c > 1).any():
            raise ValueError(f"material {self.name!r} color must be sRGB in [0, 1], got {c.tolist()}")
        if not 0 <= self.roughness <= 1:
            raise ValueError(f"material {self.name!r} roughness must be in [0, 1], got {self.roughness}")
        if not 1 <= int(self.label) <= 255:
            raise ValueError(f"material {self.name!r} label must be in [1, 255], got {self.label}")
        if not 0 < self.opacity <= 1:
            raise ValueError(f"material {self.name!r} opacity must be in (0, 1], got {self.opacity}")
        object.__setattr__(self, "color", tuple(float(x) for x in c))
        t = self.texture
        if t is not None and (not isinstance(t, np.ndarray) or t.dtype != np.uint8 or t.ndim != 3
                              or t.shape[2] != 3):
            raise ValueError(f"material {self.name!r} texture must be an (h, w, 3) uint8 array, got "
                             f"{getattr(t, 'shape', type(t).__name__)} {getattr(t, 'dtype', '')}")

    @property
    def key(self) -> tuple:
        """What a renderer needs to tell two materials apart (the texture by identity)."""
        return (self.color, self.roughness, self.double_sided, self.label,
                None if self.texture is None else id(self.texture), self.opacity)


@dataclass(frozen=True, eq=False)
class MeshItem:
    """A triangle mesh in world coordinates, one material per face.

    Parameters
    ----------
    name : str
        Unique within a scene; renderers may cache geometry under it.
    vertices : (n, 3) float
        World positions, mm.
    faces : (m, 3) int
        Triangles, counter-clockwise seen from the front.
    materials : tuple of Material
        The materials the faces use.
    face_material : (m,) int, optional
        Index into ``materials`` per face; all 0 by default.
    normals : (n, 3) float, optional
        Unit shading normals; area-weighted vertex normals by default.
    uv : (n, 2) float, optional
        Texture coordinates in [0, 1] (for textured materials).
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    materials: tuple[Material, ...]
    face_material: np.ndarray | None = None
    normals: np.ndarray | None = None
    uv: np.ndarray | None = None

    def __post_init__(self) -> None:
        V = as_float_array(self.vertices, f"{self.name}.vertices", (None, 3))
        F = np.asarray(self.faces)
        if F.ndim != 2 or F.shape[1] != 3:
            raise ValueError(f"{self.name}.faces must have shape (m, 3), got {F.shape}")
        F = as_index_array(F.ravel(), f"{self.name}.faces", len(V)).reshape(-1, 3)
        if not self.materials:
            raise ValueError(f"{self.name} needs at least one material")
        fm = np.zeros(len(F), np.int64) if self.face_material is None else as_index_array(
            self.face_material, f"{self.name}.face_material", len(self.materials))
        if fm.shape != (len(F),):
            raise ValueError(f"{self.name}.face_material must have shape ({len(F)},), got {fm.shape}")
        N = vertex_normals(V, F) if self.normals is None else as_float_array(
            self.normals, f"{self.name}.normals", (len(V), 3))
        object.__setattr__(self, "vertices", V)
        object.__setattr__(self, "faces", F)
        object.__setattr__(self, "face_material", fm)
        object.__setattr__(self, "normals", N)
        object.__setattr__(self, "materials", tuple(self.materials))
        if self.uv is not None:
            object.__setattr__(self, "uv", as_float_array(self.uv, f"{self.name}.uv", (len(V), 2)))
        if any(m.texture is not None for m in self.materials) and self.uv is None:
            raise ValueError(f"{self.name} has a textured material but no uv coordinates")


@dataclass(frozen=True)
class Light:
    """A light in world coordinates.

    Parameters
    ----------
    kind : {"directional", "point"}
    color : (3,) float
        sRGB in [0, 1].
    intensity : float
        Directional: lux-like scale; point: candela-like scale (renderer units).
    direction : (3,) float
        Directional lights: the direction the light travels (world).
    position : (3,) float
        Point lights: position, mm.
    shadows : bool
        The light casts shadows when the renderer draws shadows (fill lights usually do not).
    """

    kind: str
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    intensity: float = 3.0
    direction: tuple[float, float, float] = (0.0, 0.0, -1.0)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    shadows: bool = True

    def __post_init__(self) -> None:
        if self.kind not in ("directional", "point"):
            raise ValueError(f"light kind must be 'directional' or 'point', got {self.kind!r}")
        d = as_float_array(self.direction, "light direction", (3,))
        if self.kind == "directional" and np.linalg.norm(d) == 0:
            raise ValueError("a directional light needs a non-zero direction")
        if not np.isfinite(self.intensity) or self.intensity < 0:
            raise ValueError(f"light intensity must be >= 0, got {self.intensity}")


@dataclass(frozen=True, eq=False)
class Scene:
    """Meshes, lights, ambient light and background colour (sRGB) of one frame."""

    items: tuple[MeshItem, ...]
    lights: tuple[Light, ...] = ()
    ambient: tuple[float, float, float] = (0.25, 0.25, 0.25)
    background: tuple[float, float, float] = (0.5, 0.55, 0.6)
    labels: dict[int, str] = field(default_factory=dict)
    """Names of the material labels, for label renders."""

    def __post_init__(self) -> None:
        names = [it.name for it in self.items]
        if len(set(names)) != len(names):
            raise ValueError(f"scene item names must be unique, got {names}")
        object.__setattr__(self, "items", tuple(self.items))
        object.__setattr__(self, "lights", tuple(self.lights))
