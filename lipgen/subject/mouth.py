"""Inside the mouth: teeth, tongue and a deep, dark oral cavity, seen as the lips part.

All of it is plain triangle meshes in the model frame (:class:`MouthInterior`), drawn as
:class:`~lipgen.rig.scene.MeshItem` s and used as occluders in the visibility truth, like the
face. The upper teeth are fixed to the skull; the lower teeth and the tongue ride on the jaw,
whose motion is read from the lips: the lower lip's inner edge near the midline is carried by the
gum, so its downward displacement (never upward) moves the lower teeth and tongue down, and back
by half as much (a rotation about a hinge near the ear, about 80 mm behind and 40 mm above the
incisors, moves them down and back in that ratio).

Sizes are those of an adult's anterior teeth (crown heights 8-10 mm, of which the lips leave
the incisal 5 mm in view; widths 8.5 mm central incisor to 7 mm premolar) on a dental arch of
about 25 mm radius, the lower incisors behind the upper ones (overjet about 2 mm).
"""

from __future__ import annotations

import numpy as np

from lipgen.mesh.lipmesh import LipMesh
from lipgen.subject.head import ellipsoid

__all__ = ["MouthInterior", "TOOTH_WIDTHS"]

TOOTH_WIDTHS = (8.5, 6.5, 7.5, 7.0, 6.5)
"""Mesiodistal crown widths (mm), central incisor to second premolar (one side)."""
_ARCH_RADIUS = 25.0


def _teeth(edge_y: float, height: float, front_z: float, sign: float, radius: float):
    """Ten teeth on an arch: (vertices, faces); ``sign`` +1 for crowns growing up (upper)."""
    Vs, Fs, n = [], [], 0
    arc = np.cumsum((0,) + TOOTH_WIDTHS)
    centres = 0.5 * (arc[:-1] + arc[1:])
    for side in (-1.0, 1.0):
        for k, c in enumerate(centres):
            phi = side * c / radius
            pos = np.array([radius * np.sin(phi), edge_y + sign * height / 2,
                            front_z - radius * (1 - np.cos(phi))])
            along = np.array([np.cos(phi), 0.0, np.sin(phi)])
            out = np.array([np.sin(phi), 0.0, np.cos(phi)])
            thick = 3.2 if k < 2 else 4.0
            up = np.array([0, 1.0, 0])
            axes = np.stack([0.47 * TOOTH_WIDTHS[k] * along, 0.5 * height * up, 0.5 * thick * out])
            V, F, _ = ellipsoid(pos, axes, 6, 10)
            # flatten the ellipsoid into a crown: squash its top and bottom (a box with round edges)
            rel = V - pos
            yy = rel[:, 1] / (0.5 * height)
            V = V + (np.sign(rel[:, 1]) * 0.25 * height * (1 - yy**2))[:, None] * up
            Vs.append(V)
            Fs.append(F + n)
            n += len(V)
    return np.vstack(Vs), np.vstack(Fs)


class MouthInterior:
    """Teeth, tongue and oral cavity behind a lip mesh (model frame, mm).

    Parameters
    ----------
    mesh : LipMesh
        The lips; its rest vertices place the mouth and its lower lip carries the jaw.

    Attributes
    ----------
    parts : dict
        ``name -> (vertices (n, 3), faces (m, 3), face_part (m,) int)`` at rest; ``face_part``
        picks between a part's materials (the cavity's throat is 1).
    jaw_parts : tuple of str
        The parts that move with the jaw.
    """

    jaw_parts = ("lower_teeth", "tongue")

    def __init__(self, mesh: LipMesh) -> None:
        V = mesh.vertices
        self.rest = V
        lip = [mesh.region_names.index(r) for r in ("lip", "ridge") if r in mesh.region_names]
        on_lip = np.zeros(mesh.n_nodes, bool)
        on_lip[np.unique(mesh.faces[np.isin(mesh.regions, lip)])] = True
        lower = on_lip & (V[:, 1] < 0) & (np.abs(V[:, 0]) < 12)
        if not lower.any():
            raise ValueError(f"mesh {mesh.name!r} has no lower lip near the midline to carry the jaw")
        # the lower lip's inner edge: the highest lower-lip nodes near the midline
        top = V[lower, 1].max()
        self._jaw_nodes = np.flatnonzero(lower & (V[:, 1] >= top - 1.5))
        y0 = float(top)  # the mouth line
        mouth_z = float(V[self._jaw_nodes, 2].min())
        upper = _teeth(y0 - 0.5, 9.0, mouth_z - 7.0, 1.0, _ARCH_RADIUS)
        lower_t = _teeth(y0 - 1.0, 8.0, mouth_z - 9.5, -1.0, _ARCH_RADIUS - 1.5)
        tv, tf, _ = ellipsoid(np.array([0.0, y0 - 9.0, mouth_z - 27.0]),
                              np.stack([[0, 0, 15.0], [0, 6.0, 0], [20.0, 0, 0]]), 12, 24)
        cv, cf, _ = ellipsoid(np.array([0.0, y0 - 8.0, mouth_z - 14.0]),
                              np.stack([[0, 0, -42.0], [0, 26.0, 0], [29.0, 0, 0]]), 12, 32, np.pi / 2)
        cf = cf[:, ::-1]  # seen from inside
        throat = (cv[cf].mean(axis=1)[:, 2] < mouth_z - 14.0 - 24.0).astype(np.int64)
        self.parts = {"upper_teeth": (*upper, np.zeros(len(upper[1]), np.int64)),
                      "lower_teeth": (*lower_t, np.zeros(len(lower_t[1]), np.int64)),
                      "tongue": (tv, tf, np.zeros(len(tf), np.int64)),
                      "cavity": (cv, cf, throat)}

    def jaw_offset(self, vertices: np.ndarray) -> np.ndarray:
        """(3,) translation (mm, model frame) of the jaw's parts for lip ``vertices`` (n, 3)."""
        dy = float(np.mean(vertices[self._jaw_nodes, 1] - self.rest[self._jaw_nodes, 1]))
        dy = min(dy, 0.0)
        return np.array([0.0, dy, 0.5 * dy])

    def surfaces(self, vertices: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Model-frame geometry of each part for lip ``vertices``: ``name -> (V, F, face_part)``."""
        off = self.jaw_offset(vertices)
        return {name: (V + off if name in self.jaw_parts else V, F, fp)
                for name, (V, F, fp) in self.parts.items()}
