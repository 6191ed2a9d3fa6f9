"""USD export of lip animation: learned modes as UsdSkel blend shapes, or baked points.

Two encodings, alone or together in one file (``.usda``, ``.usdc``, ``.usd``, ``.usdz``):

* **Blend shapes.** ``/Lips`` is a ``SkelRoot`` holding a ``Skeleton`` with one dummy joint,
  bound to a ``SkelAnimation`` whose ``blendShapes`` name the modes and whose time-sampled
  ``blendShapeWeights`` animate them. The mesh carries ``SkelBindingAPI`` with
  ``skel:blendShapes``, ``skel:blendShapeTargets`` and one ``BlendShape`` child per mode.
  *The mean.* The model's mean displacement is baked into the rest points, which are
  ``mesh.vertices + mean``: all weights zero shows the mean shape, exactly as
  ``ModeModel.synthesize(0)`` does, and no extra always-on shape is needed. Mode ``i`` is
  stored as ``offsets = s_i * components_[i]`` with weight ``coef_i / s_i``, where
  ``s_i = sqrt(explained_variance_[i])`` (so weights are in standard deviations, mostly within
  ±3). With ``weight_range="unit"`` each mode becomes two shapes ``modeNN_pos`` / ``modeNN_neg``
  scaled so every weight lies in [0, 1], for importers that clamp weights to [0, 1] (Blender
  clamps shape-key values to the slider range, [0, 1] by default). The scales ``s_i`` are kept
  on the mesh as ``lipgen:modeScale``: ``coef_i = weight_i * s_i`` (signed) or
  ``(weight_pos - weight_neg) * s_i`` (unit).
* **Baked points.** The mesh's ``points`` and ``extent`` are time-sampled, one sample a frame.

With both, ``/Lips`` holds a variant set ``encoding`` (``blendShapes``, ``bakedPoints``): one
mesh topology, regions and markers, authored once; each variant adds only its animation, so a
viewer shows one lip, never two overlapping copies, and switching is a standard USD selection.

Stage metadata: ``upAxis = "Y"`` (the model frame is y-up), ``metersPerUnit = 0.001`` (mm),
``timeCodesPerSecond = framesPerSecond = fps``, start and end time codes, ``defaultPrim``.
Regions are a ``GeomSubset`` partition (family ``region``); markers are a ``Points`` prim that
moves with the lips in both encodings.
"""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path

import numpy as np

from lipgen._io import atomic_path
from lipgen._optional import require
from lipgen._validate import as_float_array, check_finite
from lipgen.usd.author import BAKED_POINTS, BLEND_SHAPES, ENCODING_SET, Plan, author_stage, float_extent
from lipgen.usd.read import UsdAnimation, ValidationIssue, read_animation, validate

__all__ = ["export_usd", "read_animation", "validate", "UsdAnimation", "ValidationIssue",
           "EXTENSIONS", "ENCODING_SET", "BLEND_SHAPES", "BAKED_POINTS", "check_start", "MAX_START"]

log = logging.getLogger(__name__)

EXTENSIONS = (".usda", ".usdc", ".usd", ".usdz")
"""File extensions :func:`export_usd` writes: text, crate, either, and a zipped package."""
_CHUNK = 2048  # frames per block when bounding the blend-shape animation


def _check_extension(path: str | os.PathLike) -> str:
    ext = Path(path).suffix.lower()
    if ext not in EXTENSIONS:
        raise ValueError(f"cannot write USD to {str(path)!r}: unknown extension {ext!r}; "
                         f"use one of {', '.join(EXTENSIONS)}")
    return ext


def _identifier(name: str) -> str:
    from pxr import Tf

    return Tf.MakeValidIdentifier(str(name)) or "lips"


def _mode_arrays(mesh, model):
    """(mean (n, 3), components (k, n, 3), std (k,)) from a fitted model, checked against ``mesh``."""
    for attr in ("mean_", "components_"):
        if not hasattr(model, attr):
            raise TypeError(f"model must be a fitted lipgen.modes.ModeModel (no attribute {attr!r}); "
                            "call fit() or ModeModel.load() first")
    if hasattr(model, "check_mesh"):
        model.check_mesh(mesh)
    n = mesh.n_nodes
    mean = as_float_array(model.mean_, "model.mean_", (3 * n,)).reshape(n, 3)
    comps = as_float_array(model.components_, "model.components_", (None, 3 * n))
    if len(comps) == 0:
        raise ValueError("model has no modes (components_ has shape (0, 3n))")
    var = getattr(model, "explained_variance_", None)
    std = np.sqrt(np.clip(np.asarray(var, np.float64), 0, None)) if var is not None else np.ones(len(comps))
    std = np.where(np.isfinite(std) & (std > 0), std, 1.0)
    return mean, comps.reshape(len(comps), n, 3), std


MAX_START = 10**9
"""Largest |start| time code: time codes are doubles, and at 1e20 every frame fell on the same one."""


def check_start(start) -> None:
    """Refuse a first time code that is not a whole number in [-:data:`MAX_START`, :data:`MAX_START`]."""
    if isinstance(start, bool) or not isinstance(start, int | np.integer):
        raise TypeError(f"start must be an integer time code, got {start!r}")
    if abs(int(start)) > MAX_START:
        raise ValueError(f"start time code {start} is beyond +-{MAX_START:.0e}: the frames' time codes "
                         "(doubles) would fall together; give a smaller --start")


def _blend_shape_plan(mesh, model, weights, weight_range):
    """Rest points, shape names, offsets (float32) and per-frame shape weights (float32)."""
    mean, comps, std = _mode_arrays(mesh, model)
    k = len(comps)
    if weights is None:
        W = np.zeros((0, k))
    else:
        W = as_float_array(weights, "weights", finite=False)
        if W.ndim != 2 or W.shape[1] != k:
            raise ValueError(f"weights must have shape (F, {k}): one column per mode of the model, "
                             f"which has {k} modes; got shape {W.shape}")
        if len(W) == 0:  # an empty file, not the bare modes (weights=None)
            raise ValueError(f"weights has no frames (shape {W.shape}); give at least one frame, or no "
                             "weights for the bare modes")
        check_finite(W, "weights")
    rest = mesh.vertices + mean
    if weight_range == "signed":
        scale = std
        names = [f"mode{i:02d}" for i in range(k)]
        offsets = comps * scale[:, None, None]
        shape_w = W / scale
    elif weight_range == "unit":
        peak = np.abs(W).max(axis=0) if len(W) else np.zeros(k)
        scale = np.where(peak > 0, peak, std)
        names = [f"mode{i:02d}_{s}" for i in range(k) for s in ("pos", "neg")]
        offsets = np.stack([comps * scale[:, None, None], -comps * scale[:, None, None]], axis=1)
        offsets = offsets.reshape(2 * k, *comps.shape[1:])
        shape_w = np.stack([np.clip(W, 0, None), np.clip(-W, 0, None)], axis=2).reshape(len(W), 2 * k)
        shape_w = shape_w / np.repeat(scale, 2)
    else:
        raise ValueError(f"weight_range must be 'signed' or 'unit', got {weight_range!r}")
    return (_check_float32(rest, "rest points (mesh + model mean)"), names,
            _check_float32(offsets, "blend-shape offsets"), _check_float32(shape_w, "weights"), scale)


def _skel_extent(rest32, offsets32, weights32) -> np.ndarray:
    """Bound of every frame's deformed points, from the float32 values USD holds, padded by a
    bound on the float32 rounding of a consumer's blend-shape sum."""
    n = len(rest32)
    # Coordinate-major (x of every node, then y, then z) so the min/max run over contiguous memory.
    rest = rest32.astype(np.float64).T.reshape(-1)
    O = offsets32.astype(np.float64).transpose(0, 2, 1).reshape(len(offsets32), -1)
    W = weights32.astype(np.float64)
    lo, hi = rest32.min(axis=0).astype(np.float64), rest32.max(axis=0).astype(np.float64)
    for a in range(0, len(W), _CHUNK):
        P = (rest + W[a:a + _CHUNK] @ O).reshape(-1, 3, n)
        lo, hi = np.minimum(lo, P.min(axis=(0, 2))), np.maximum(hi, P.max(axis=(0, 2)))
    magnitude = np.abs(rest).max() + (np.abs(W).max(axis=0, initial=0) @ np.abs(O).max(axis=1))
    pad = 4 * (len(O) + 2) * np.finfo(np.float32).eps * magnitude
    return float_extent(np.stack([lo, hi]), pad=pad)


def _check_float32(arr, name: str) -> np.ndarray:
    """``arr`` as float32, refusing values that are finite in float64 but not in float32 (USD
    stores points, offsets and weights as float32: 1e39 would be written as inf)."""
    arr = np.asarray(arr)
    with np.errstate(over="ignore", invalid="ignore"):
        out = arr.astype(np.float32)
    if not np.isfinite(out).all():
        big = np.abs(arr[~np.isfinite(out)]).max() if np.isfinite(arr).all() else float("nan")
        raise ValueError(f"{name} (shape {arr.shape}) has values beyond float32's range (|x| up to "
                         f"{big:.3g}; USD stores float32, at most {np.finfo(np.float32).max:.3g}); "
                         "nothing was written")
    return out


def _build_plan(mesh, model, weights, points, weight_range, root, markers, regions, start) -> Plan:
    n = mesh.n_nodes
    if weights is not None and model is None:
        raise ValueError("weights were given without a model; pass model=ModeModel.load(...) too")
    baked = None
    if points is not None:
        P = as_float_array(points, "points", (None, n, 3))
        if len(P) == 0:
            raise ValueError("points has no frames (shape (0, n, 3))")
        baked = _check_float32(P, "points")
    _check_float32(mesh.vertices, "mesh vertices")
    rest = skel_extent = None
    names, offsets, shape_w, attrs = [], np.zeros((0, n, 3), np.float32), np.zeros((0, 0), np.float32), {}
    if model is not None:
        rest, names, offsets, shape_w, scale = _blend_shape_plan(mesh, model, weights, weight_range)
        skel_extent = _skel_extent(rest, offsets, shape_w)
        if not np.isfinite(skel_extent).all():
            raise ValueError("weights drive the blend shapes beyond float32's range (the deformed points' "
                             f"bound is {np.asarray(skel_extent).tolist()}); nothing was written")
        attrs["modeScale"] = scale
    n_frames = len(baked) if baked is not None else len(shape_w)
    if baked is not None and model is not None and weights is not None and len(shape_w) != len(baked):
        raise ValueError(f"weights has {len(shape_w)} frames but points has {len(baked)}; "
                         "both encodings of one file share the frames")
    if baked is None and model is None:
        baked = mesh.vertices[None].astype(np.float32)  # a still mesh
        n_frames = 0
    region_list = []
    if regions:  # subsets are children of the mesh, beside the blend shapes: keep the names apart
        for code, rname in enumerate(mesh.region_names):
            idx = np.flatnonzero(mesh.regions == code)
            name = _identifier(rname)
            if len(idx):
                region_list.append((f"{name}_region" if name in names else name, idx))
    marker_nodes = mesh.markers if markers else np.zeros(0, np.int64)
    mesh_name = _identifier(mesh.name)
    if mesh_name in ("Skel", "markers"):  # the root's other children
        mesh_name += "_mesh"
    return Plan(root=_identifier(root), mesh_name=mesh_name, markers_name="markers",
                faces=mesh.faces, regions=region_list, times=start + np.arange(n_frames, dtype=np.float64),
                rest=rest, shape_names=names, offsets=offsets, shape_weights=shape_w,
                skel_extent=skel_extent, baked=baked, marker_nodes=np.asarray(marker_nodes),
                marker_names=tuple(mesh.marker_names) if markers else (), attrs=attrs)


def export_usd(path: str | os.PathLike, mesh, model=None, weights=None, points=None, fps: float = 30,
               *, start: int = 0, weight_range: str = "signed", markers: bool = True,
               regions: bool = True, root: str = "Lips", default_encoding: str = BLEND_SHAPES) -> Path:
    """Write a lip animation to a USD file, atomically.

    Parameters
    ----------
    path : str or PathLike
        Destination; the extension chooses the format: ``.usda`` (text), ``.usdc`` / ``.usd``
        (binary crate), ``.usdz`` (a package holding one ``.usdc``).
    mesh : lipgen.LipMesh
        Topology, rest vertices (mm), regions and markers.
    model : lipgen.modes.ModeModel, optional
        Fitted modes: written as blend shapes (rest points = ``mesh.vertices + mean_``).
    weights : (F, k) float, optional
        Mode coefficients per frame, as ``model.synthesize`` takes them (mm). Without them the
        modes are written with all weights zero (a rig to animate elsewhere).
    points : (F, n, 3) float, optional
        Vertex positions per frame (mm): written as baked time-sampled points with extents.
    fps : float
        Frames per second; frame ``i`` is at time code ``start + i``.
    start : int
        Time code of the first frame.
    weight_range : {"signed", "unit"}
        Blend-shape weights in standard deviations of each mode (one shape a mode), or in
        [0, 1] with a positive and a negative shape a mode (for importers that clamp).
    markers, regions : bool
        Also write the markers as a ``Points`` prim / the regions as ``GeomSubset``s.
    root : str
        Name of the root (default) prim.
    default_encoding : {"blendShapes", "bakedPoints"}
        The variant selected when both encodings are written.

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    ValueError
        Unknown extension, weights with the wrong number of modes, non-finite weights or
        points, frame counts that disagree, bad fps. The destination is left untouched.
    """
    ext = _check_extension(path)
    fps = float(fps)
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be a positive number, got {fps}")
    if default_encoding not in (BLEND_SHAPES, BAKED_POINTS):
        raise ValueError(f"default_encoding must be {BLEND_SHAPES!r} or {BAKED_POINTS!r}, "
                         f"got {default_encoding!r}")
    require("pxr", "USD export")  # fails early, with the install hint
    check_start(start)
    plan = _build_plan(mesh, model, weights, points, weight_range, root, markers, regions, float(start))
    from pxr import Sdf, Usd, UsdGeom

    layer = Sdf.Layer.CreateAnonymous("lipgen.usdc")
    stage = Usd.Stage.Open(layer)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 0.001)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    n_frames = len(plan.times)
    stage.SetStartTimeCode(float(start))
    stage.SetEndTimeCode(float(start + max(n_frames - 1, 0)))
    layer.customLayerData = {"lipgen": {"topologyId": mesh.topology_id, "weightRange": weight_range,
                                        "frames": n_frames}}
    author_stage(stage, plan, default_encoding)
    dest = Path(path)
    with atomic_path(dest) as tmp:
        _write_layer(layer, tmp, ext, dest.stem)
    log.info("wrote %s (%d frames, %s)", dest, n_frames,
             "+".join(e for e, on in ((BLEND_SHAPES, plan.rest is not None),
                                      (BAKED_POINTS, points is not None)) if on))
    return dest


def _write_layer(layer, tmp: Path, ext: str, stem: str) -> None:
    """Write ``layer`` to the temporary file ``tmp`` in the format of ``ext``.

    ``.usdz`` is a package holding the stage as one ``.usdc`` root layer named ``stem``.
    """
    from pxr import UsdUtils

    if ext != ".usdz":
        if not layer.Export(str(tmp)):
            raise OSError(f"USD could not write {tmp}")
        return
    # the work folder sits beside the destination under its temporary name, so a killed export's
    # leftovers are found and removed by the next one (lipgen._io.remove_stale_temporaries)
    with tempfile.TemporaryDirectory(prefix=f"{tmp.name}-pkg-", dir=tmp.parent) as work:
        inner = Path(work) / f"{_identifier(stem)}.usdc"
        if not layer.Export(str(inner)):
            raise OSError(f"USD could not write {inner}")
        tmp.unlink()  # the packager refuses to overwrite the empty placeholder
        if not UsdUtils.CreateNewUsdzPackage(str(inner), str(tmp)):
            raise OSError(f"USD could not package {inner} into {tmp}")

