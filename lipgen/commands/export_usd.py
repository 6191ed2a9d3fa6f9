"""``lipgen export-usd``: write a lip animation to USD (blend shapes, baked points, or both)."""

from __future__ import annotations

import argparse
import importlib
import sys
import zipfile
from pathlib import Path

import numpy as np

from lipgen.commands._output import add_force, check_file_output

_EPILOG = """\
examples:
  lipgen export-usd --model model.npz --weights weights.npy --fps 30 --out lips.usda
  lipgen export-usd --model model.npz --script "AA EE OO M:0.3" --bake --out speech.usdc
  lipgen export-usd --dataset DATASET --out truth.usdc     (a dataset's ground truth, baked)
  lipgen export-usd --model model.npz --weights weights.npz --out lips.usdz --weight-range unit
  lipgen export-usd --model model.npz --out rig.usdc          (the modes, all weights zero)

The mesh is the default procedural lips (--resolution) unless --mesh gives a LipMesh file
(LipMesh.save). --weights takes an .npy array (F, k) of mode coefficients, as
ModeModel.project returns them, or an .npz holding one array (or one named "weights").

--script runs a viseme script on the synthetic subject (lipgen.subject.motion: visemes -> muscle-like
activations -> simulated vertices) and projects its displacements onto the model's modes;
--bake adds the simulated vertices themselves as baked points.

--dataset exports a dataset's ground-truth vertices (lipgen generate) as baked points on its
subject mesh, at its frame rate; with --model (a model of that mesh) the truth is also
projected onto the modes and written as blend shapes.

--points adds baked points (F, n, 3) in mm. With a model as well, both encodings go into one
file as the variant set "encoding". Blender clamps shape-key values to [0, 1] on import: use
--weight-range unit for files meant for Blender's importer.
"""


def add_parser(sub) -> None:
    p = sub.add_parser(
        "export-usd",
        help="write lip animation to USD: learned modes as UsdSkel blend shapes and/or baked points",
        description="Write a lip animation to a USD file (.usda, .usdc, .usd, .usdz): the model's modes "
        "as UsdSkel blend shapes with animated weights, baked time-sampled points, or both. The "
        "file is written atomically and then checked with USD's validators (pxr.UsdValidation).",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--model", help="fitted ModeModel file (.npz, ModeModel.save)")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--weights", help="mode coefficients per frame: .npy (F, k) or .npz")
    src.add_argument("--script", help='viseme script, e.g. "AA:0.3 EE OO M:0.15" (NAME[:SECONDS], '
                     "0.2 s by default), simulated on the synthetic subject and projected on the modes")
    src.add_argument("--dataset", help="dataset folder (lipgen generate): export its ground-truth "
                     "animation as baked points")
    p.add_argument("--bake", action="store_true", help="with --script: also write the simulated vertices "
                   "as baked points")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the synthetic subject for --script (default 0)")
    p.add_argument("--points", help="baked vertex positions per frame: .npy (F, n, 3) in mm")
    p.add_argument("--mesh", help="LipMesh file (.npz, LipMesh.save); default: the procedural lips")
    p.add_argument("--resolution", type=int, default=0, help="resolution of the procedural lips (default 0)")
    p.add_argument("--fps", type=float, default=None,
                   help="frames per second (default: the dataset's with --dataset, else 30)")
    p.add_argument("--start", type=int, default=0, help="time code of the first frame (default 0)")
    p.add_argument("--weight-range", choices=("signed", "unit"), default="signed",
                   help="blend-shape weights in standard deviations, one shape a mode (signed), or in "
                   "[0, 1] with a positive and a negative shape a mode (unit; for Blender)")
    p.add_argument("--default-encoding", choices=("blendShapes", "bakedPoints"), default="blendShapes",
                   help="variant selected when both encodings are written")
    p.add_argument("--no-markers", action="store_true", help="do not write the markers as a Points prim")
    p.add_argument("--no-regions", action="store_true", help="do not write the regions as GeomSubsets")
    p.add_argument("--no-validate", action="store_true", help="skip the validation after writing")
    p.add_argument("--out", required=True, help="output file; the extension chooses the format")
    add_force(p)
    p.set_defaults(func=_run)


def _load_array(path: str, what: str, key: str) -> np.ndarray:
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{what} file not found: {p}")
    if p.suffix not in (".npy", ".npz"):
        raise ValueError(f"{what} must be an .npy or .npz file, got {p.name!r}")
    try:
        with open(p, "rb") as fh:
            if p.suffix == ".npy":
                return np.load(fh, allow_pickle=False)
            with np.load(fh, allow_pickle=False) as data:
                if key in data.files:
                    return data[key]
                if len(data.files) == 1:
                    return data[data.files[0]]
                raise ValueError(f"{p} holds arrays {data.files}; name the {what} array {key!r}")
    except (EOFError, OSError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{what} file {p} is empty, truncated or not a numpy {p.suffix} file "
                         f"({exc})") from exc
    except ValueError as exc:
        if str(p) in str(exc):
            raise
        raise ValueError(f"{what} file {p} cannot be read: {exc}") from exc


def _mesh(args):
    from lipgen.mesh.lipmesh import LipMesh

    if args.mesh:
        return LipMesh.load(args.mesh)
    lipgen = importlib.import_module("lipgen")
    if not hasattr(lipgen, "lip_mesh"):
        raise ValueError("this lipgen has no procedural lips (lipgen.lip_mesh); pass --mesh MESH.npz")
    return lipgen.lip_mesh(args.resolution)


def _script_motion(args, mesh, model, fps):
    """Weights (F, k) and vertices (F, n, 3) of a viseme script on the synthetic subject.

    The subject lives on a finer procedural mesh whose first nodes are the nodes of the coarser
    ones (lipgen.subject.motion), so its motion is read off the model's nodes directly.
    """
    from lipgen.subject import motion

    if args.mesh:
        raise ValueError("--script needs the procedural lips (--resolution), not --mesh: the synthetic "
                         "subject moves the procedural mesh's nodes")
    subject = motion.default_subject(args.seed, resolution=max(1, args.resolution))
    n = mesh.n_nodes
    if subject.mesh.n_nodes < n or not np.allclose(subject.mesh.vertices[:n], mesh.vertices, atol=1e-9):
        raise ValueError(f"the synthetic subject's mesh does not contain lip_mesh({args.resolution})'s nodes")
    sim = motion.simulate(subject, motion.viseme_activations(args.script, fps=fps), fps=fps)
    U = sim.displacements[:, :n]
    return model.project(U), mesh.vertices + U


def _dataset_truth(args):
    """The subject mesh, ground-truth vertices (F, n, 3) and fps of a dataset folder."""
    from lipgen.dataset.layout import Dataset

    for flag, value in (("--mesh", args.mesh), ("--points", args.points)):
        if value:
            raise ValueError(f"--dataset brings its own mesh and points; drop {flag}")
    ds = Dataset(args.dataset)
    if len(ds) == 0:
        raise ValueError(f"dataset {args.dataset} has no frames")
    ds.require_truth("lipgen export-usd --dataset")
    vertices = np.stack([ds.truth(i)["vertices"] for i in range(len(ds))])
    return ds.mesh, vertices, ds.fps


def _run(args) -> int:
    from lipgen.modes.model import ModeModel
    from lipgen.usd.export import _check_extension, check_start, export_usd, validate

    check_file_output(args.out, args.force)
    _check_extension(args.out)
    check_start(args.start)
    if args.fps is not None and not 1 <= args.fps <= 1000:  # as generate and lipsync; NaN fails too
        raise ValueError(f"--fps must be in [1, 1000], got {args.fps}")  # 1e9 simulated 3e8 frames
    if not (args.model or args.points or args.dataset):
        raise ValueError("nothing to export: give --model (with --weights or --script, or alone for the "
                         "bare modes), --points, or --dataset")
    points = None
    model = ModeModel.load(args.model) if args.model else None
    if args.dataset:
        mesh, points, fps = _dataset_truth(args)
    else:
        mesh, fps = _mesh(args), 30.0
    fps = fps if args.fps is None else args.fps
    weights = None
    if args.weights:
        if model is None:
            raise ValueError("--weights needs --model (the modes the weights drive)")
        weights = _load_array(args.weights, "weights", "weights")
    elif args.script:
        if model is None:
            raise ValueError("--script needs --model (the simulated motion is projected onto its modes)")
        weights, simulated = _script_motion(args, mesh, model, fps)
        if args.bake:
            points = simulated
    elif args.dataset and model is not None:  # the truth on the modes, beside the baked truth
        model.check_mesh(mesh)
        weights = model.project(points - mesh.vertices)
    if args.bake and not args.script:
        raise ValueError("--bake goes with --script (use --points to add other baked points)")
    if args.points:
        if points is not None:
            raise ValueError("--points and --bake both give baked points; choose one")
        points = _load_array(args.points, "points", "points")
    out = export_usd(args.out, mesh, model, weights, points, fps=fps, start=args.start,
                     weight_range=args.weight_range, markers=not args.no_markers,
                     regions=not args.no_regions, default_encoding=args.default_encoding)
    n = len(weights) if weights is not None else (len(points) if points is not None else 0)
    kinds = [k for k, on in (("blend shapes", model is not None), ("baked points", points is not None)) if on]
    sys.stdout.write(f"wrote {out}: {n} frame(s) at {fps:g} fps, {' + '.join(kinds)}\n")
    if args.no_validate:
        return 0
    issues = validate(out)
    for issue in issues:
        sys.stdout.write(f"  {issue}\n")
    errors = sum(i.is_error for i in issues)
    sys.stdout.write(f"validation: {errors} error(s), {len(issues) - errors} other finding(s)\n")
    return 1 if errors else 0
