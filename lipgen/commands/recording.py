"""``lipgen recording init``: a camera-mirror video and chessboard photos -> a dataset folder."""

from __future__ import annotations

import argparse
import json
import sys

_EPILOG = """\
Builds the dataset layout (manifest.json, raw/NNNNNN.png from the video or the frame folder,
calib/NNNNNN.png from the photos, mesh.npz: the model mesh whose 16 markers and nose dot are
inked on the lips) with no truth/, ready for lipgen reconstruct, train, show and nrsfm (lipgen
evaluate needs truth).

The calibration photos show a printed chessboard (--board: inner corners and square size) seen
directly and in the mirror, from the same camera at the video's resolution; at least 4, better
10-20 in varied poses. Each photo's reprojection error is printed, and photos whose board fits
far worse than the others (blur, a misdetected board) are dropped with a message.

The split column (the mirror's edge) is found as the sharpest brightness step down the frame,
and the mirror side as the darker half (a mirror reflects less than all light); give --split /
--mirror-side when the detection is wrong or says it cannot tell (the calibration cannot: the rig
with the halves swapped fits the boards as well, but mirrors the face).
Nothing is written unless every input is good; an existing --out is kept unless --force.

examples:
  lipgen recording init take1.mp4 --calib boards/ --out rec1
  lipgen recording init take1.mp4 --calib boards/ --out rec1 --mirror-side left --split 960
  lipgen recording init frames/ --fps 60 --calib boards/ --out rec2     (a folder of frame images)
  lipgen reconstruct rec1 --out rec1_recon.npz
"""


def _board(text: str) -> tuple[int, int, float]:
    try:
        c, r, s = text.lower().split("x")
        return int(c), int(r), float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"board must look like 9x6x8 (inner cols x inner rows x square mm), "
                                         f"got {text!r}") from None


def _split(text: str):
    if text == "auto":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"split must be a column number or 'auto', got {text!r}") from None


def add_footage_options(q) -> None:
    """The options that describe a recording's rig and ink (shared with ``lipgen reconstruct``)."""
    q.add_argument("--mirror-side", default="auto", choices=("auto", "left", "right"),
                   help="which half of the frame is the mirror (default: detected, the darker half)")
    q.add_argument("--split", type=_split, default="auto",
                   help="first column of the right half (default: detected, the mirror's edge)")
    q.add_argument("--board", type=_board, default=(9, 6, 8.0),
                   help="chessboard inner corners and square size, COLSxROWSxMM (default 9x6x8)")
    q.add_argument("--dot-diameter", type=float, default=2.0, help="ink dot diameter, mm (default 2)")
    q.add_argument("--fps", type=float, default=None,
                   help="frame rate (default: the video's; 30 for a folder of frames)")


def add_parser(sub) -> None:
    p = sub.add_parser("recording", help="bring your own camera-mirror recording into the dataset layout",
                       description="Work with recordings of real footage (no ground truth).",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    rsub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    q = rsub.add_parser("init", help="build a dataset folder from a video and chessboard photos",
                        description="Build a dataset folder from a camera-mirror video and a folder of "
                        "chessboard calibration photos.", epilog=_EPILOG,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    q.add_argument("video", metavar="FOOTAGE",
                   help="the camera-mirror video (any format ffmpeg decodes: mp4, mov, avi, ...) or a folder "
                   "of its frames as images (png, jpg, tif, bmp; in name order)")
    q.add_argument("--calib", required=True, help="folder of chessboard photos (png, jpg, tif, bmp)")
    q.add_argument("--out", required=True, help="dataset folder to create")
    add_footage_options(q)
    q.add_argument("--mesh", default="lip_mesh(0)",
                   help="model mesh whose markers were inked (default lip_mesh(0))")
    q.add_argument("--force", action="store_true", help="replace --out if it exists")
    q.add_argument("--no-progress", action="store_true", help="no progress bar")
    q.set_defaults(func=_run)


def _run(args) -> int:
    from lipgen.recon.recording import init_recording

    summary = init_recording(args.video, args.calib, args.out, mirror_side=args.mirror_side, split=args.split,
                             board=args.board, dot_diameter=args.dot_diameter, mesh_source=args.mesh,
                             force=args.force, progress=not args.no_progress, fps=args.fps)
    report_recording(summary, args.out, sys.stdout.write)
    if args.verbose:
        sys.stdout.write(json.dumps(summary, indent=1) + "\n")
    return 0


def report_recording(summary: dict, out, w) -> None:
    """Write what ``init_recording`` found (per-photo errors, dropped photos, mirror, split) with ``w``."""
    w("calibration photo       virtual px   real px\n")
    for row in summary["calibration"]["per_image_rms_px"]:
        cells = ["   -   " if row[v] is None else f"{row[v]:7.3f}" for v in ("virtual", "real")]
        w(f"  {row['file']:<20} {cells[0]:>10}   {cells[1]:>7}\n")
    for d in summary["calibration"]["dropped"]:
        w(f"dropped: {d['file']} ({d['view']} view, {d['rms_px']:.2f} px RMS)\n")
    w(f"calibration {summary['calibration_rms_px']['all']:.3f} px RMS; mirror on the "
      f"{summary['mirror_side']} "
      f"(its half has {100 * summary['brightness_ratio']:.0f}% of the other's light), split column "
      f"{summary['split']}\n")
    w(f"wrote {out}: {summary['frames']} frames of {summary['size'][0]}x{summary['size'][1]} at "
      f"{summary['fps']:g} fps\n")
