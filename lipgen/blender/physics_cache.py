"""The factorised physics of a mesh, cached in memory by content.

Factorising K_s is the expensive step (seconds on a fine mesh); every force, reach goal and
preview after it is a cheap solve. The add-on asks for the physics of an object's rest shape
and stiffness settings each time it needs it; this cache answers from memory when nothing that
matters changed. The key is a hash of the content (rest positions, faces, regions, anchors,
stiffness, Poisson ratio), so undo, renaming, duplicating and reloading a .blend file never
give a stale answer: a file that was just opened simply rebuilds on first use. Nothing of it
is saved in the .blend.
"""

from __future__ import annotations

import hashlib
import logging
import threading
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from lipgen._validate import as_float_array
from lipgen.mesh.lipmesh import REGIONS, LipMesh

__all__ = ["PhysicsSpec", "physics_for", "clear_physics_cache", "cached_count", "MAX_CACHED"]

log = logging.getLogger(__name__)

MAX_CACHED = 4
"""Physics objects kept at once (least recently used goes first)."""

_CACHE: OrderedDict[str, object] = OrderedDict()
_LOCK = threading.Lock()


@dataclass(frozen=True, eq=False)
class PhysicsSpec:
    """Everything the physics of one mesh depends on.

    Parameters
    ----------
    vertices : (n, 3) float
        Rest positions in millimetres.
    faces : (m, 3) int
        Triangles.
    regions : (m,) int
        Region code per face, an index into :data:`lipgen.mesh.REGIONS`.
    anchors : (a,) int
        Grounded nodes.
    stiffness : tuple of (str, float)
        Young's modulus E per region name.
    poisson : float
        Poisson ratio (the thesis uses 0.01).
    markers : (k,) int
        Marker nodes (kept on the mesh; they do not change the physics).
    name : str
        Label for messages.
    """

    vertices: np.ndarray
    faces: np.ndarray
    regions: np.ndarray
    anchors: np.ndarray
    stiffness: tuple[tuple[str, float], ...]
    poisson: float = 0.01
    markers: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    name: str = "lips"

    def __post_init__(self) -> None:
        object.__setattr__(self, "vertices", as_float_array(self.vertices, "vertices", (None, 3)))
        object.__setattr__(self, "faces", np.asarray(self.faces, dtype=np.int64))
        object.__setattr__(self, "regions", np.asarray(self.regions, dtype=np.int64))
        object.__setattr__(self, "anchors", np.asarray(self.anchors, dtype=np.int64))
        object.__setattr__(self, "markers", np.asarray(self.markers, dtype=np.int64))
        stiff = tuple((str(k), float(v)) for k, v in self.stiffness)
        unknown = [k for k, _ in stiff if k not in REGIONS]
        if unknown:
            raise ValueError(f"stiffness names unknown region(s) {unknown}; regions are {REGIONS}")
        bad = [(k, v) for k, v in stiff if not np.isfinite(v) or v <= 0]
        if bad:
            raise ValueError(f"stiffness E must be positive and finite, got {bad}")
        if not 0.0 <= float(self.poisson) < 0.5:
            raise ValueError(f"poisson must be in [0, 0.5), got {self.poisson}")
        object.__setattr__(self, "stiffness", stiff)

    @property
    def key(self) -> str:
        """A hash of everything the factorisation depends on."""
        h = hashlib.sha1()
        for arr in (self.vertices.astype("<f8"), self.faces.astype("<i8"), self.regions.astype("<i8"),
                    np.sort(self.anchors).astype("<i8")):
            h.update(np.int64(arr.size).tobytes())
            h.update(np.ascontiguousarray(arr).tobytes())
        h.update(repr((sorted(self.stiffness), float(self.poisson))).encode())
        return h.hexdigest()

    def mesh(self) -> LipMesh:
        """The :class:`lipgen.LipMesh` (validated; raises :class:`lipgen.MeshError` if broken)."""
        return LipMesh(self.vertices, self.faces, self.regions, self.anchors, self.markers,
                       name=self.name)


def physics_for(spec: PhysicsSpec):
    """The :class:`lipgen.fem.Physics` for ``spec``, from the cache or built and factorised now.

    Raises
    ------
    lipgen.MeshError
        If the mesh is broken for the element (degenerate or duplicate faces, loose vertices).
    lipgen.SingularStiffnessError
        If the anchors do not ground the mesh (none, or parts not attached to any).
    """
    from lipgen.fem import Physics

    key = spec.key
    with _LOCK:
        hit = _CACHE.get(key)
        if hit is not None:
            _CACHE.move_to_end(key)
            return hit
    log.info("building physics for %s (%d nodes)", spec.name, len(spec.vertices))
    physics = Physics(spec.mesh(), stiffness=dict(spec.stiffness), poisson=spec.poisson)
    with _LOCK:
        _CACHE[key] = physics
        while len(_CACHE) > MAX_CACHED:
            _CACHE.popitem(last=False)
    return physics


def clear_physics_cache() -> None:
    """Forget every cached physics (the add-on calls this when it is disabled)."""
    with _LOCK:
        _CACHE.clear()


def cached_count() -> int:
    """How many physics objects the cache holds."""
    return len(_CACHE)
