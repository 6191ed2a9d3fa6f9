"""``lipgen show``: a picture of one dataset frame with its truth projections."""

from __future__ import annotations

import argparse
import sys


def add_parser(sub) -> None:
    p = sub.add_parser(
        "show", help="save an annotated picture of a dataset frame",
        description="Save the raw camera-mirror frame with the truth projections of the 16 markers and "
        "the nose drawn in both halves: circles where a mark is visible, crosses where it is hidden "
        "(occluded, facing away or outside the view), each with its name.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("dataset", help="dataset folder written by lipgen generate")
    p.add_argument("--frame", type=int, default=0, help="frame number")
    p.add_argument("--out", required=True, help="picture to write (.png, .pdf, .svg)")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from lipgen.dataset.layout import Dataset, save_annotated

    ds = Dataset(args.dataset)
    if not 0 <= args.frame < len(ds):
        raise ValueError(f"--frame {args.frame} is out of range: {args.dataset} has frames 0..{len(ds) - 1}")
    out = save_annotated(ds, args.frame, args.out)
    sys.stdout.write(f"wrote {out}\n")
    return 0
