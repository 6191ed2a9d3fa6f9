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
        epilog="examples:\n  lipgen show data/s0 --frame 10 --out s0.png\n"
        "  lipgen show data/easy0 --beside data/hard0 --frame 10 --out easy_vs_hard.png",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset", help="dataset folder written by lipgen generate")
    p.add_argument("--frame", type=int, default=0, help="frame number (default 0)")
    p.add_argument("--out", required=True, help="picture to write (.png, .pdf, .svg)")
    p.add_argument("--beside", default=None, metavar="DATASET",
                   help="show the same frame of another dataset beside it (e.g. a --preset hard one beside "
                   "an easy one), titled with their presets, with close-ups of the mouth")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from lipgen.dataset.layout import Dataset, save_annotated

    ds = Dataset(args.dataset)
    if args.beside is not None:
        from lipgen.dataset.pictures import save_side_by_side

        out = save_side_by_side([ds, Dataset(args.beside)], args.frame, args.out)
        sys.stdout.write(f"wrote {out}\n")
        return 0
    if not 0 <= args.frame < len(ds):
        raise ValueError(f"--frame {args.frame} is out of range: {args.dataset} has frames 0..{len(ds) - 1}")
    out = save_annotated(ds, args.frame, args.out)
    sys.stdout.write(f"wrote {out}\n")
    return 0
