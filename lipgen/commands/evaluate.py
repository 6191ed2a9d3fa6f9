"""``lipgen evaluate``: score a reconstruction and a trained model against the dataset's truth."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from lipgen.commands._output import add_force, check_folder_output, check_not_input

_EPILOG = """\
REPORT/report.md gets the calibration against the true rig, the tracking error per mark (px), the
3-D marker error after triangulation (mm), the normalisation error, the marker displacements
against the true ones (measured from the reconstruction's rest: lipgen reconstruct --rest; their
per-marker constant offset), the Table 5.1 analogue (rows
xyz 8 points, yz, xy; columns 10 modes, full covariance, combined model, physics; against the
reach fields and against the TRUE surface), the variance captured against the number of modes,
and pictures. report.json holds the same figures.

examples:
  lipgen evaluate data/s0 --model model.npz --recon recon.npz --out report/
  lipgen evaluate data/s0 --model model.npz --out report/     (reconstructs first)
"""


def add_parser(sub) -> None:
    p = sub.add_parser("evaluate", help="score reconstruction and model against the dataset's ground truth",
                       description="Compare every stage of the reconstruction, and the trained model's LLSE "
                       "on the held-out frames, with the dataset's ground truth; write a report.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset", help="dataset folder written by lipgen generate")
    p.add_argument("--model", required=True, help="model from lipgen train (.npz)")
    p.add_argument("--recon", help="reconstruction of this dataset (default: run lipgen reconstruct)")
    p.add_argument("--out", required=True, help="report folder (created)")
    p.add_argument("--test-frames", type=int, default=None, help="as given to lipgen train")
    p.add_argument("--rest", choices=("model", "recording", "auto"), default=None,
                   help="without --recon: where the reconstruction measures displacements from (as lipgen "
                   "reconstruct --rest; default: the kind the model was trained on, else model). A --recon "
                   "file's own choice is used as recorded")
    p.add_argument("--rest-from", default=None, metavar="RECON",
                   help="without --recon: measure from another reconstruction's rest (as lipgen reconstruct "
                   "--rest-from), e.g. the training recording's")
    add_force(p, "the report files in --out")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from lipgen.dataset.layout import Dataset
    from lipgen.evaluate.report import REPORT_FILES, nrsfm_section, write_report
    from lipgen.evaluate.scoring import score
    from lipgen.modes.model import ModeModel
    from lipgen.recon.pipeline import Reconstruction, model_mesh, reconstruct_dataset

    products = REPORT_FILES + (() if args.recon else ("recon.npz",))
    out = check_folder_output(args.out, args.force, products)
    for name in products:
        check_not_input(out / name, (args.dataset, args.model, args.recon, args.rest_from))
    model = ModeModel.load(args.model)
    ds = Dataset(args.dataset)
    ds.require_truth("lipgen evaluate")       # before any work: nothing is written without truth
    for flag, value in (("--rest", args.rest), ("--rest-from", args.rest_from)):
        if args.recon and value is not None:
            raise ValueError(f"{flag} {value} applies when evaluate reconstructs; the reconstruction "
                             f"{args.recon} records its own rest (reconstruct again with {flag} to "
                             "change it)")
    if args.recon:
        recon = Reconstruction.load(args.recon)
    else:
        # by default, from the kind of rest the model was trained on (lipgen train records it)
        from lipgen.recon.restsource import check_rest_from, check_rest_options, rest_frames

        trained = (model.provenance_ or {}).get("rest_kind")
        rest = args.rest or (trained if trained in ("model", "recording") and not args.rest_from else None)
        check_rest_options(args.rest, args.rest_from)  # before the report folder is made
        if args.rest_from is not None:
            if not Path(args.rest_from).is_file():
                raise FileNotFoundError(f"--rest-from {args.rest_from}: no such file (a reconstruction "
                                        "written by lipgen reconstruct --rest recording)")
            check_rest_from(Reconstruction.load(args.rest_from), model_mesh(), args.rest_from)
        if rest == "recording":  # too few training frames: refused before the report folder is made
            rest_frames(len(ds), args.test_frames)
        model.check_mesh(model_mesh())  # a model of another mesh: before the reconstruction, not after
        out.mkdir(parents=True, exist_ok=True)
        recon = reconstruct_dataset(args.dataset, test_frames=args.test_frames, rest=rest,
                                    rest_from=args.rest_from)
        recon.save(out / "recon.npz")
    mesh = model_mesh(recon.info["mesh_source"])
    s = score(ds, model, recon, args.test_frames, mesh)
    extra = {"Non-rigid SfM on one view": nrsfm_section(ds, recon)}
    path = write_report(out, s, ds, model, recon, mesh, extra)
    sys.stdout.write(f"3-D markers {s['triangulation']['rms_mm']:.3f} mm RMS, normalisation "
                     f"{s['normalisation']['rms_mm']:.3f} mm RMS; report: {path}\n")
    return 0
