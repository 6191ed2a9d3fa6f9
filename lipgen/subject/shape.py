"""A shape space for the truth subject: lips that differ from the model's and from each other.

The reconstruction model keeps ``lip_mesh()`` (or the user's mesh). The truth subject's rest
shape is that mesh warped by :func:`shaped_mesh` to the anatomical measurements of a
:class:`ShapeParams`, drawn per subject by :func:`sample_shape` from ``--subject-seed`` (separate
from the motion's ``--seed``). The warp keeps the topology, regions, anchors, marker nodes and the
nose: node i of the truth is still the anatomical point of node i of the model (so displacements
can be compared node for node), but it sits elsewhere at rest.

Ranges (:data:`SHAPE_RANGES`) and population means (:data:`SHAPE_MEANS`)
---------------------------------------------------------------------------
Linear soft-tissue measurements of young adults from Farkas' anthropometry (L.G. Farkas,
*Anthropometry of the Head and Face*, 2nd ed., Raven Press 1994; Farkas, Katic & Forrest,
"International anthropometric study of facial morphology in various ethnic groups/races",
J Craniofac Surg 16(4):615-646, 2005). The ranges are roughly the pooled male and female mean ±
2 SD, rounded outwards:

- ``width`` (ch-ch, cheilion to cheilion): means 50-56 mm, SD 3-4 mm -> 44-62 mm;
- ``upper_vermilion`` (ls-sto, labrale superius to the inner contour): about 8-9 mm, SD 1.3-1.5
  -> 5-12 mm;
- ``lower_vermilion`` (sto-li): about 9-10 mm, SD 1.5-1.9 -> 6-14 mm;
- ``cupid_bow`` (height of the bow's peaks above its dip at the midline): 0.5-3.5 mm;
- ``philtrum_depth`` (the groove's depth below its ridges, just above the vermilion border):
  0-2.5 mm;
- ``protrusion`` (the lips forward of the model's, relative to the face around them, as the
  spread of lip position about Ricketts' E-line and Burstone's Sn-Pog' line, a few mm): -3..+3 mm;
- ``fullness`` (extra forward bulge of the vermilion over its border): -1.5..+2.5 mm;
- ``corner_depth`` (how far the corners sit behind labrale superius, set by the curve of the
  dental arch): 9-17 mm;
- ``asymmetry`` (the subject's left corner above the right): -2..+2 mm; faces are never exactly
  symmetric, and mouth-corner height differences of 1-2 mm are common in normal adults.

The first three are measured norms; the other six are less standardised and their ranges are
estimates of normal variation, given here so the truth never falls outside plausible faces.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np

from lipgen.mesh.lipmesh import LipMesh

__all__ = ["ShapeParams", "SHAPE_RANGES", "SHAPE_MEANS", "SHAPE_SDS", "sample_shape", "shaped_mesh",
           "measure_shape", "model_shape", "MAX_SUBJECT_SEED"]

MAX_SUBJECT_SEED = 2**32 - 1
"""The largest subject seed accepted."""

SHAPE_RANGES: dict[str, tuple[float, float]] = {
    "width": (44.0, 62.0),
    "upper_vermilion": (5.0, 12.0),
    "lower_vermilion": (6.0, 14.0),
    "cupid_bow": (0.5, 3.5),
    "philtrum_depth": (0.0, 2.5),
    "protrusion": (-3.0, 3.0),
    "fullness": (-1.5, 2.5),
    "corner_depth": (9.0, 17.0),
    "asymmetry": (-2.0, 2.0),
}
"""Parameter -> (low, high) in mm; see the module docstring for the sources."""

SHAPE_MEANS: dict[str, float] = {"width": 53.0, "upper_vermilion": 8.6, "lower_vermilion": 9.9,
                                 "cupid_bow": 1.8, "philtrum_depth": 1.0, "protrusion": 0.0,
                                 "fullness": 0.5, "corner_depth": 13.0, "asymmetry": 0.0}
"""Population means (mm) that :func:`sample_shape` draws around."""

SHAPE_SDS: dict[str, float] = {"width": 3.6, "upper_vermilion": 1.4, "lower_vermilion": 1.7,
                               "cupid_bow": 0.6, "philtrum_depth": 0.5, "protrusion": 1.2,
                               "fullness": 0.8, "corner_depth": 1.8, "asymmetry": 0.8}
"""Population standard deviations (mm) of :func:`sample_shape`'s truncated normals."""

_ARCH_RADIUS = 35.0  # mm, the dental arch of the procedural mesh (z = -x^2 / 70)


@dataclass(frozen=True)
class ShapeParams:
    """A subject's lip shape (mm); every field must lie in :data:`SHAPE_RANGES`."""

    width: float
    upper_vermilion: float
    lower_vermilion: float
    cupid_bow: float
    philtrum_depth: float
    protrusion: float
    fullness: float
    corner_depth: float
    asymmetry: float

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            lo, hi = SHAPE_RANGES[f.name]
            if isinstance(v, bool) or not isinstance(v, int | float | np.floating | np.integer):
                raise TypeError(f"shape parameter {f.name} must be a number in mm, got {v!r}")
            if not np.isfinite(v) or not lo <= float(v) <= hi:
                raise ValueError(f"shape parameter {f.name} = {v!r} mm is outside its documented range "
                                 f"[{lo}, {hi}] mm (lipgen.subject.shape.SHAPE_RANGES)")

    def to_dict(self) -> dict:
        """The shape parameters as a JSON-ready dict (mm)."""
        return {k: float(v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict) -> ShapeParams:
        """Shape parameters from a dict (written by :meth:`to_dict`), each checked against its range."""
        names = {f.name for f in fields(cls)}
        unknown, missing = set(d) - names, names - set(d)
        if unknown or missing:
            raise ValueError(f"shape parameters must be exactly {sorted(names)}; unknown {sorted(unknown)}, "
                             f"missing {sorted(missing)}")
        return cls(**{k: float(v) for k, v in d.items()})


def _check_subject_seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
        raise TypeError(f"subject seed must be a whole number in [0, {MAX_SUBJECT_SEED}], got {seed!r}")
    if not 0 <= int(seed) <= MAX_SUBJECT_SEED:
        raise ValueError(f"subject seed {seed} is outside [0, {MAX_SUBJECT_SEED}]")
    return int(seed)


def sample_shape(subject_seed: int) -> ShapeParams:
    """The shape of subject ``subject_seed``: independent normals (:data:`SHAPE_MEANS`,
    :data:`SHAPE_SDS`) truncated to :data:`SHAPE_RANGES` by redrawing."""
    rng = np.random.default_rng([_check_subject_seed(subject_seed), 0x5A9E])
    out = {}
    for name, (lo, hi) in SHAPE_RANGES.items():
        while True:
            v = rng.normal(SHAPE_MEANS[name], SHAPE_SDS[name])
            if lo <= v <= hi:
                out[name] = float(v)
                break
    return ShapeParams(**out)


def _landmarks(mesh: LipMesh) -> dict[str, np.ndarray]:
    names = ("upper_mid", "lower_mid", "corner_left", "corner_right", "bow_dip", "bow_peak_left",
             "bow_peak_right", "lower_border_mid")
    missing = [n for n in names if n not in mesh.marker_names]
    if missing:
        raise ValueError(f"the shape space needs the default markers; mesh {mesh.name!r} lacks {missing}")
    return {n: mesh.vertices[mesh.marker_index(n)] for n in names}


def _inner_midline(mesh: LipMesh) -> tuple[float, float]:
    """y of the inner contour (ridge's free edge) at the midline, upper and lower (mm)."""
    ridge = mesh.region_nodes("ridge") if "ridge" in mesh.region_names else np.arange(mesh.n_nodes)
    V = mesh.vertices[ridge]
    mid = V[np.abs(V[:, 0]) < 1e-6]
    if len(mid) < 2:
        raise ValueError(f"mesh {mesh.name!r} has no ridge nodes on the midline; cannot measure its lips")
    up, lo = mid[mid[:, 1] > 0], mid[mid[:, 1] < 0]
    return float(up[:, 1].min()), float(lo[:, 1].max())


def measure_shape(mesh: LipMesh) -> dict[str, float]:
    """Measure a rest mesh with the default markers: the fields of :class:`ShapeParams` (mm).

    Width is corner to corner; vermilion heights run from the inner contour at the midline to
    labrale superius (``bow_dip``) and labrale inferius (``lower_border_mid``); the bow's peaks
    sit above its dip; protrusion is labrale superius' z relative to the default model's;
    fullness is ``upper_mid`` forward of labrale superius, relative to the default model; the
    philtrum depth is measured 4 mm above the dip against points 5 mm to each side (the dental
    arch's curvature removed); corner depth is ``upper_mid``'s z minus the corners'. Values may
    fall outside :data:`SHAPE_RANGES` for meshes that are not lips.
    """
    L = _landmarks(mesh)
    ref = _landmarks(_reference())
    up0, lo0 = _inner_midline(mesh)
    V = mesh.vertices
    d = L["bow_dip"]

    from scipy.interpolate import LinearNDInterpolator

    skin = V[mesh.region_nodes("skin")] if "skin" in mesh.region_names else V
    skin = skin[skin[:, 1] > d[1] - 1.0]  # the skin above the upper lip: a height field z(x, y)
    z_at = LinearNDInterpolator(skin[:, :2], skin[:, 2])


    arch = 5.0**2 / (2 * _ARCH_RADIUS)
    sides = z_at([d[0] - 5, d[0] + 5], [d[1] + 4, d[1] + 4])
    phil = float(np.mean(sides) + arch - z_at(d[0], d[1] + 4))
    corners = 0.5 * (L["corner_left"][2] + L["corner_right"][2])
    return {
        "width": float(L["corner_left"][0] - L["corner_right"][0]),
        "upper_vermilion": float(d[1] - up0),
        "lower_vermilion": float(lo0 - L["lower_border_mid"][1]),
        "cupid_bow": float(0.5 * (L["bow_peak_left"][1] + L["bow_peak_right"][1]) - d[1]),
        "philtrum_depth": float(phil),
        "protrusion": float(d[2] - ref["bow_dip"][2]),
        "fullness": float((L["upper_mid"][2] - d[2]) - (ref["upper_mid"][2] - ref["bow_dip"][2])),
        "corner_depth": float(L["upper_mid"][2] - corners),
        "asymmetry": float(L["corner_left"][1] - L["corner_right"][1])}


_REF: dict = {}


def _reference() -> LipMesh:
    if "mesh" not in _REF:
        from lipgen.mesh.procedural import lip_mesh

        _REF["mesh"] = lip_mesh(0)
    return _REF["mesh"]


def model_shape() -> ShapeParams:
    """The default model mesh's own measurements (the shape the model assumes)."""
    if "shape" not in _REF:
        _REF["shape"] = ShapeParams(**measure_shape(_reference()))
    return _REF["shape"]


def _vermilion_weight(mesh: LipMesh) -> np.ndarray:
    """(n,) weight: 1 inside the vermilion and ridge, about 1/4 on the vermilion border, 0 beyond."""
    ids = [mesh.region_names.index(r) for r in ("lip", "ridge") if r in mesh.region_names]
    w = np.zeros(mesh.n_nodes)
    w[np.unique(mesh.faces[np.isin(mesh.regions, ids)])] = 1.0
    w[np.unique(mesh.faces[np.isin(mesh.regions, [mesh.region_names.index("skin")])])] = 0.0
    e = np.unique(np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)
    deg = np.bincount(e.ravel(), minlength=mesh.n_nodes).astype(float)
    s = np.bincount(e[:, 0], w[e[:, 1]], mesh.n_nodes) + np.bincount(e[:, 1], w[e[:, 0]], mesh.n_nodes)
    return np.maximum(w, 0.5 * s / np.maximum(deg, 1))  # a soft edge at the border


def _ramp(y: np.ndarray, at: float) -> np.ndarray:
    """Piecewise-linear weight in y: 0 at y = 0, 1 from ``at`` on (on the side of ``at``'s sign)."""
    return np.clip(y / at, 0.0, 1.0)


def _warp(mesh: LipMesh, delta: dict[str, float]) -> np.ndarray:
    """(n, 3) rest vertices of ``mesh`` moved by ``delta`` (parameter -> mm change, roughly)."""
    L = _landmarks(mesh)
    X = mesh.vertices
    x, y, z = X[:, 0], X[:, 1], X[:, 2]
    half = 0.5 * float(L["corner_left"][0] - L["corner_right"][0])
    yb_up, yb_lo = L["bow_dip"][1], L["lower_border_mid"][1]
    # vertical: the vermilion heights stretch the lips between the mouth line and the borders
    # (the skin beyond moves with the border: a taller lip is a longer face, not squeezed skin)
    ny = y + delta["upper_vermilion"] * _ramp(y, yb_up) - delta["lower_vermilion"] * _ramp(y, yb_lo)
    # Cupid's bow: raise (or lower) the two peaks on the upper vermilion border
    xp = abs(L["bow_peak_left"][0])
    peaks = np.clip(np.exp(-(((np.abs(x) - xp) / 2.5) ** 2)) - np.exp(-((xp / 2.5) ** 2)), 0, None)
    ny += delta["cupid_bow"] * peaks * _ramp(y, yb_up) * np.exp(-(np.clip(y - yb_up, 0, None) / 4.0) ** 2)
    # asymmetry: the subject's left corner up, the right down, fading away from the mouth line
    ny += 0.5 * delta["asymmetry"] * np.clip(x / half, -1.5, 1.5) * np.exp(-((y / 20.0) ** 2))
    # depth: protrusion of the lips, fullness of the vermilion, the corners, the philtrum
    lips = np.exp(-((x / (1.3 * half)) ** 4)) * np.exp(-(((y + 3.0) / 18.0) ** 4))
    verm = _vermilion_weight(mesh) * np.clip(1 - (x / half) ** 2, 0, None)
    nz = z + delta["protrusion"] * lips + delta["fullness"] * verm / max(verm.max(), 1e-9)
    nz -= delta["corner_depth"] * (x / half) ** 2 * np.exp(-((y / 15.0) ** 2))
    groove = np.exp(-((x / 3.0) ** 2)) * np.exp(-(((y - yb_up - 4.0) / 3.5) ** 2)) * (y > yb_up)
    nz -= delta["philtrum_depth"] * groove
    nx = x * (1.0 + delta["width"] / (2 * half))
    return np.stack([nx, ny, nz], axis=1)


def shaped_mesh(mesh: LipMesh, params: ShapeParams, iterations: int = 6) -> LipMesh:
    """``mesh`` (the default procedural lips, any resolution) warped to the shape ``params``.

    Topology, regions, anchors, markers (as node indices) and the nose are kept; only the rest
    vertices move, smoothly and (for parameters in range) monotonically in x and y. The warp's
    amounts are corrected a few times by measuring the result (:func:`measure_shape`), so that
    the result measures ``params`` to within about 0.1 mm.
    """
    from dataclasses import replace

    if not isinstance(params, ShapeParams):
        raise TypeError(f"params must be a ShapeParams (see sample_shape), got {type(params).__name__}")
    base = measure_shape(mesh)
    ref = model_shape().to_dict()
    off = max(abs(base[k] - ref[k]) for k in ("width", "upper_vermilion", "lower_vermilion", "corner_depth"))
    if off > 0.05:
        raise ValueError(f"shaped_mesh warps the default procedural lips only; mesh {mesh.name!r} differs "
                         f"from them by up to {off:.3g} mm in its measurements {base}")
    names = list(base)
    want = np.array([params.to_dict()[k] for k in names])
    have = np.array([base[k] for k in names])

    def measured(d):
        V = _warp(mesh, dict(zip(names, d, strict=True)))
        got = measure_shape(replace(mesh, vertices=V))
        return V, np.array([got[k] for k in names])

    # the measurements are (nearly) linear in the warp's amounts: a Jacobian by unit steps, then
    # Newton steps with it (protrusion, fullness and corner depth share landmarks)
    J = np.stack([measured(np.eye(len(names))[i])[1] - have for i in range(len(names))], axis=1)
    d = np.linalg.solve(J, want - have)
    for _ in range(iterations):
        V, got = measured(d)
        if np.abs(want - got).max() < 1e-3:
            break
        d = d + np.linalg.solve(J, want - got)
    return replace(mesh, vertices=V, name=f"{mesh.name}_shaped")
