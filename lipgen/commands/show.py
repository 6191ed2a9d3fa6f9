"""``lipgen show``: a picture of one dataset frame with its truth projections (or its tracks)."""

from __future__ import annotations

import argparse
import sys

from lipgen.commands._output import add_force, check_not_input, check_picture_output

_EPILOG = """\
A dataset without truth (a recording made with lipgen recording init) shows the raw frame alone;
--recon adds the marks tracked by lipgen reconstruct (plus signs), with or without truth.

examples:
  lipgen show data/s0 --frame 10 --out frame10.png
  lipgen show rec --frame 0 --recon recon.npz --out tracked0.png
"""


def add_parser(sub) -> None:
    p = sub.add_parser(
        "show", help="save an annotated picture of a dataset frame",
        description="Save the raw camera-mirror frame with the truth projections of the 16 markers and "
        "the nose drawn in both halves: circles where a mark is visible, crosses where it is hidden "
        "(occluded, facing away or outside the view), each with its name.",
        epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset", help="dataset folder (lipgen generate, or lipgen recording init)")
    p.add_argument("--frame", type=int, default=0, help="frame number (default 0)")
    p.add_argument("--recon", help="also draw the marks tracked in this reconstruction (.npz)")
    p.add_argument("--out", required=True, help="picture to write (.png, .pdf, .svg)")
    p.add_argument("--beside", default=None, metavar="DATASET",
                   help="show the same frame of another dataset beside it (e.g. a --preset hard one beside "
                   "an easy one), titled with their presets, with close-ups of the mouth")
    add_force(p)
    p.set_defaults(func=_run)


def _run(args) -> int:
    from lipgen.dataset.layout import Dataset, save_annotated
    from lipgen.errors import DatasetError

    check_picture_output(args.out, args.force)
    check_not_input(args.out, (args.dataset, args.recon, args.beside))
    ds = Dataset(args.dataset)
    if args.beside is not None:
        from lipgen.dataset.pictures import save_side_by_side

        out = save_side_by_side([ds, Dataset(args.beside)], args.frame, args.out)
        sys.stdout.write(f"wrote {out}\n")
        return 0
    if not 0 <= args.frame < len(ds):
        raise ValueError(f"--frame {args.frame} is out of range: {args.dataset} has frames 0..{len(ds) - 1}")
    tracked = None
    if args.recon:
        from lipgen.recon.pipeline import Reconstruction
        from lipgen.rig.camera import VIEWS

        recon = Reconstruction.load(args.recon)
        if recon.uv.shape[1:3] != (len(ds), len(ds.marks)):
            raise DatasetError(f"{args.recon} tracks {recon.uv.shape[1]} frames x {recon.uv.shape[2]} marks, "
                               f"but {args.dataset} has {len(ds)} x {len(ds.marks)}: it is not a "
                               "reconstruction of this dataset")
        tracked = [ds.rig.to_raw(view, recon.uv[v, args.frame]) for v, view in enumerate(VIEWS)]
    out = save_annotated(ds, args.frame, args.out, tracked=tracked)
    sys.stdout.write(f"wrote {out}\n")
    return 0
