"""Reading USD animation back with UsdSkel, and checking files with ``pxr.UsdValidation``.

Part of :mod:`lipgen.usd` (import the names from there). Reading works on any file, not only
lipgen's: skinned prims (blend shapes, joints, or both) are evaluated by
``UsdSkel.BakeSkinning`` on an in-memory flattened copy of the stage, so the file on disk is
never touched; other point-based prims are read from their ``points`` time samples.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lipgen._optional import require

__all__ = ["UsdAnimation", "ValidationIssue", "read_animation", "validate"]


@dataclass(frozen=True)
class UsdAnimation:
    """Per-frame points of one prim of a USD file.

    Attributes
    ----------
    times : (F,) float
        Time codes of the frames (the stage's start code for a still prim).
    points : (F, n, 3) float
        Points in millimetres (converted with the stage's ``metersPerUnit``), in the stage's
        world frame (the prim's local-to-world transform applied at each time).
    fps : float
        The stage's ``timeCodesPerSecond``.
    prim_path : str
    up_axis : str
        The stage's up axis (``"Y"`` for lipgen files); points are not rotated.
    skinned : bool
        True when the points were computed by UsdSkel (blend shapes and/or joints).
    """

    times: np.ndarray
    points: np.ndarray
    fps: float
    prim_path: str
    up_axis: str
    skinned: bool

    @property
    def seconds(self) -> np.ndarray:
        """(F,) time of each frame in seconds from the first frame."""
        return (self.times - self.times[0]) / self.fps


def _open_stage(path: str | os.PathLike):
    require("pxr", "reading USD")
    from pxr import Sdf, Usd

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"no such USD file: {p}")
    cached = Sdf.Layer.Find(str(p))
    if cached:  # the layer registry would hand back a stale copy of a file rewritten since
        cached.Reload(True)
    stage = Usd.Stage.Open(str(p))
    if stage is None:
        raise ValueError(f"USD could not open {p}")
    return stage


def _is_skinned(prim) -> bool:
    from pxr import UsdSkel

    return bool(UsdSkel.BindingAPI(prim).GetInheritedSkeleton()) and bool(UsdSkel.Root.Find(prim))


def _pick_prim(stage, prim_path: str | None):
    from pxr import UsdGeom

    if prim_path is not None:
        prim = stage.GetPrimAtPath(prim_path)
        if not prim or not prim.IsA(UsdGeom.PointBased):
            raise ValueError(f"{prim_path!r} is not a point-based prim (Mesh, Points, ...) of the stage")
        return prim
    root = stage.GetDefaultPrim() or stage.GetPseudoRoot()
    meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh) and p.GetPath().HasPrefix(root.GetPath())]
    if not meshes:
        raise ValueError(f"{stage.GetRootLayer().identifier} has no Mesh prim under {root.GetPath()}; "
                         "pass prim= the path of a point-based prim")
    animated = [p for p in meshes
                if _is_skinned(p) or UsdGeom.Mesh(p).GetPointsAttr().GetNumTimeSamples() > 0]
    return (animated or meshes)[0]


def read_animation(path: str | os.PathLike, prim: str | None = None) -> UsdAnimation:
    """Per-frame points of a mesh in a USD file, evaluated with UsdSkel where it is skinned.

    Parameters
    ----------
    path : str or PathLike
        Any USD file (``.usda``, ``.usdc``, ``.usd``, ``.usdz``).
    prim : str, optional
        Path of a point-based prim. By default the first animated Mesh under the default prim
        (the first Mesh if none is animated). With a variant set, the selected variant is read.

    Returns
    -------
    UsdAnimation
    """
    from pxr import Usd, UsdGeom, UsdSkel

    stage = _open_stage(path)
    target = _pick_prim(stage, prim)
    skinned = _is_skinned(target)
    if skinned:
        stage = Usd.Stage.Open(stage.Flatten())  # bake into a copy in memory, never the file
        if not UsdSkel.BakeSkinning(stage.Traverse()):
            raise ValueError(f"UsdSkel could not evaluate the skinning of {target.GetPath()} in {path}")
        target = stage.GetPrimAtPath(target.GetPath())
    attr = UsdGeom.PointBased(target).GetPointsAttr()
    times = list(attr.GetTimeSamples())
    codes = [Usd.TimeCode(t) for t in times] or [Usd.TimeCode.Default()]
    mm = UsdGeom.GetStageMetersPerUnit(stage) / 0.001
    frames = []
    for code in codes:
        pts = attr.Get(code)
        if pts is None:
            raise ValueError(f"{target.GetPath()} has no points at time {code}")
        P = np.asarray(pts, dtype=np.float64)
        M = np.asarray(UsdGeom.XformCache(code).GetLocalToWorldTransform(target), dtype=np.float64)
        if not np.array_equal(M, np.eye(4)):
            P = P @ M[:3, :3] + M[3, :3]  # USD matrices act on row vectors
        frames.append(P * mm if mm != 1.0 else P)
    out_times = np.asarray(times if times else [stage.GetStartTimeCode()], dtype=np.float64)
    return UsdAnimation(times=out_times, points=np.stack(frames), fps=float(stage.GetTimeCodesPerSecond()),
                        prim_path=str(target.GetPath()), up_axis=str(UsdGeom.GetStageUpAxis(stage)),
                        skinned=skinned)


@dataclass(frozen=True)
class ValidationIssue:
    """One finding of a ``pxr.UsdValidation`` validator."""

    severity: str
    """"Error", "Warn" or "Info"."""
    name: str
    message: str
    validator: str
    sites: tuple[str, ...]
    variant: str
    """The variant selection the stage was validated under ("" for the file as composed)."""

    @property
    def is_error(self) -> bool:
        return self.severity == "Error"

    def __str__(self) -> str:
        where = f" [{self.variant}]" if self.variant else ""
        return f"{self.severity}{where} {self.validator}/{self.name}: {self.message}"


def _issues(ctx, stage, variant: str) -> list[ValidationIssue]:
    out = []
    for err in ctx.Validate(stage):
        if err.HasNoError():
            continue
        sites = []
        for site in err.GetSites():
            if site.IsPrim():
                sites.append(str(site.GetPrim().GetPath()))
            elif site.IsProperty():
                sites.append(str(site.GetProperty().GetPath()))
        validator = err.GetValidator()
        vname = validator.GetMetadata().name if validator else ""
        out.append(ValidationIssue(severity=err.GetType().displayName or str(err.GetType()).split(".")[-1],
                                   name=str(err.GetName()), message=err.GetMessage(), validator=vname,
                                   sites=tuple(sites), variant=variant))
    return out


def validate(path: str | os.PathLike, all_variants: bool = True) -> list[ValidationIssue]:
    """Run every registered ``pxr.UsdValidation`` validator on a USD file.

    usd-core ships no ``usdchecker``; this is its library form. With ``all_variants``, a
    default prim holding the ``encoding`` variant set is validated once per variant as well.

    Returns
    -------
    list of ValidationIssue
        Empty when nothing was found; filter with ``issue.is_error``.
    """
    stage = _open_stage(path)
    from pxr import UsdValidation

    registry = UsdValidation.ValidationRegistry()
    ctx = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    issues = _issues(ctx, stage, "")
    root = stage.GetDefaultPrim()
    from lipgen.usd.author import ENCODING_SET

    if all_variants and root and root.GetVariantSets().HasVariantSet(ENCODING_SET):
        vset = root.GetVariantSets().GetVariantSet(ENCODING_SET)
        stage.SetEditTarget(stage.GetSessionLayer())  # selections go to the session layer only
        for name in vset.GetVariantNames():
            vset.SetVariantSelection(name)
            issues += _issues(ctx, stage, f"{ENCODING_SET}={name}")
    return issues
