"""``lipgen reconstruct``: from a dataset's raw frames to displacement fields of the model."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from lipgen.commands._output import check_file_output, check_not_input
from lipgen.commands.recording import add_footage_options, report_recording

REST_CHOICES, DEFAULT_REST = ("model", "recording", "auto"), "model"
"""As :mod:`lipgen.recon.restsource`'s (not imported here: the parser starts fast; a test checks them)."""

_EPILOG = """\
steps: calibrate the camera and the mirror from the dataset's chessboard frames; detect and track
the ink dots in both views (normalised correlation; the dots matched to the model's markers on the
first of frames 0, 5, 10, ... where every marker is matched in both views, then tracked forward to
the end and backward to frame 0; --anchor-step 0 starts at frame 0 whatever it shows; then the
clip is tracked again in reverse, from its last frame (or the first probed frame from the end with
every marker matched), and where the two runs put a marker on different dots the run whose 3-D
points lie clearly nearer the model's layout keeps it, else the first run; a marker the first run
lacks is filled from the second where the runs agree: --no-cross-check tracks once, in 50-65 %
of the tracking time, and leaves the labels of the first run unchecked);
triangulate (closest point between rays); normalise (by default: the head rotation about the
nose that leaves the least force on the model, one scale from the most neutral frame; or the
thesis's section 3 lip planes with --normalisation thesis); and per frame the field of the
model reaching the markers with the least-norm force (Physics.reach, thesis eq 4.3). The ground
truth is not read.

Displacements are measured from rest. --rest recording: the recording's own rest, each marker's
median over the training frames nearest the model's rest (speech pauses), at the rig's metric
scale; the held-out tail (--test-frames) is not used. --rest-from TRAIN.npz: the rest (and frame
of reference) of another reconstruction of the same subject, e.g. a test utterance measured from
the training recording's rest. --rest model (the default): the model's rest markers (right when
the subject's lips have the model's shape, as on the easy preset). --rest auto: the recording's
rest when its rest frames come from two or more pauses, else (one stretch may be a held posture;
fewer than 10 training frames) the model's, with a warning; use it (or --rest recording) for speech
with pauses. The choice is recorded in the output; lipgen train and evaluate use it.

Every marker sighting is accounted for: accepted (both views agree), rejected (the views disagree,
or a pose outlier), unpaired (one view only) or lost. The summary per marker goes to stderr, and
each marker never tracked in a view is named there with the reason. Exit status: 0 on success;
3 when a whole marker has no accepted sighting (the reconstruction is written, but misses it),
unless --allow-missing (then 0, with the same warnings); 1 on an error (nothing written).
The dataset needs no truth/ folder: a recording of real footage (lipgen recording init) works.

Real footage can also be given directly: a video file or a folder of frame images, with --calib
(a folder of chessboard photos). The recording folder is then built first, as lipgen recording
init builds it (at --recording; default: beside --out, named after it), and reconstructed.

examples:
  lipgen reconstruct data/s0 --out recon.npz
  lipgen reconstruct data/lowres --out recon.npz --allow-missing
  lipgen reconstruct data/s0 --mesh my_lips.npz --out recon.npz
  lipgen reconstruct data/s0 --anchor-step 0 --out recon.npz      (track from frame 0)
  lipgen reconstruct data/long --no-cross-check --out recon.npz    (track once: faster)
  lipgen reconstruct data/take2 --rest-from recon.npz --out take2.npz   (take2 from take 1's rest)
  lipgen reconstruct take1.mp4 --calib boards/ --out take1.npz     (writes take1_recording/ too)
  lipgen reconstruct frames/ --fps 60 --calib boards/ --out f.npz --recording rec_f
"""


def add_parser(sub) -> None:
    p = sub.add_parser("reconstruct", help="reconstruct displacement fields from a dataset's raw frames",
                       description="Calibrate, track, triangulate, normalise and reach: turn a dataset's raw "
                       "camera-mirror frames into per-frame displacement fields of the model mesh.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset", help="dataset folder (lipgen generate, or lipgen recording init: no truth); "
                   "or, with --calib, a video file or a folder of frame images")
    p.add_argument("--out", required=True, help="output file (.npz); an existing file is kept unless --force")
    p.add_argument("--mesh", default="lip_mesh(0)",
                   help="model mesh: 'lip_mesh(R)' (default lip_mesh(0)) or a LipMesh file (.npz)")
    p.add_argument("--normalisation", default="least-force",
                   choices=("thesis", "least-force", "least-strain", "procrustes"),
                   help="how the head pose is removed (default least-force; see lipgen.recon.normalize)")
    p.add_argument("--test-frames", type=int, default=None,
                   help="held-out tail that lipgen train will use (default: 10, a fifth of short sequences); "
                   "the normalisation's reference frame is chosen before it")
    p.add_argument("--reference-frames", type=_frames, default=None, metavar="LIST",
                   help="frames the normalisation may take its reference (most neutral) frame from, e.g. "
                   "'0-20' or '3,7,12' (default: all training frames)")
    p.add_argument("--rest", choices=REST_CHOICES, default=None,
                   help=f"where displacements are measured from: the model's rest markers, the recording's "
                   f"rest (its training frames), or auto (the recording's when its rest frames come "
                   f"from 2 or more pauses, else the model's); default {DEFAULT_REST}")
    p.add_argument("--rest-from", default=None, metavar="RECON",
                   help="measure from the rest of another reconstruction (lipgen reconstruct --rest "
                   "recording) of the same subject and mesh, e.g. the training recording's")
    p.add_argument("--allow-missing", action="store_true",
                   help="exit 0 even when a whole marker was never accepted (default: exit status 3)")
    p.add_argument("--calib", default=None,
                   help="folder of chessboard photos: DATASET is then real footage (a video or frame folder)")
    p.add_argument("--recording", default=None,
                   help="with --calib: the recording folder to build (default: OUT's name + '_recording')")
    add_footage_options(p)
    p.add_argument("--force", action="store_true", help="overwrite --out (and --recording) if they exist")
    p.add_argument("--anchor-step", type=_non_negative, default=None, metavar="N",
                   help="frames between the frames tried as the tracking's start (the first with every "
                        "marker matched in both views is taken; frame 0 when it is one or none is); 0: start "
                        "at frame 0; default: the library's (ReconstructSettings.anchor_step, 5)")
    p.add_argument("--no-cross-check", action="store_true",
                   help="track the clip once (from the anchor frame), not a second time from its end to "
                   "check the labels: in 50-65 %% of the tracking time")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_run)


def _non_negative(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = -1
    if n < 0:
        raise argparse.ArgumentTypeError(f"must be a whole number of frames >= 0 (0: start at frame 0), got "
                                         f"{text!r}")
    return n


MAX_LISTED_FRAMES = 10**6
"""The most frames a frame list may name (as many as lipgen generate makes)."""


def _frames(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.strip().partition("-")
        try:
            lo, hi = int(a), int(b or a)
        except ValueError:
            raise argparse.ArgumentTypeError(f"frames must look like '0-20' or '3,7,12', "
                                             f"got {text!r}") from None
        if hi < lo:
            raise argparse.ArgumentTypeError(f"frame range {part.strip()!r} is empty ({hi} < {lo}); write "
                                             f"'{hi}-{lo}'")
        if len(out) + hi - lo + 1 > MAX_LISTED_FRAMES:
            raise argparse.ArgumentTypeError(f"frames {text!r} name more than {MAX_LISTED_FRAMES} frames")
        out += range(lo, hi + 1)
    return out


MISSING_STATUS = 3
"""Exit status of ``lipgen reconstruct`` when a whole marker was never accepted."""


def _dataset_or_recording(args, out: Path) -> Path:
    """The dataset folder to reconstruct: ``args.dataset`` itself, or the recording built from footage."""
    from lipgen.errors import DatasetError

    src = Path(args.dataset)
    if args.calib is None:
        if src.is_dir() and not (src / "manifest.json").is_file() or src.is_file():
            raise DatasetError(f"{src} is not a dataset folder (no manifest.json); to reconstruct real "
                               "footage (a video file or a folder of frame images) give --calib, a folder of "
                               "chessboard photos")
        return src
    if (src / "manifest.json").is_file():
        raise DatasetError(f"{src} is already a dataset folder; drop --calib (it is calibrated from its "
                           "calib/ folder)")
    rec = Path(args.recording) if args.recording else out.with_name(out.stem + "_recording")
    if rec.resolve() == out.resolve():  # the recording would be made, reconstructed, then not saved
        raise ValueError(f"--recording {rec} is --out itself; the recording is a folder and --out a file")
    # init_recording checks the rest of --recording (overlaps with the footage, a non-empty folder) first
    from lipgen.recon.recording import init_recording

    summary = init_recording(src, args.calib, rec, mirror_side=args.mirror_side, split=args.split,
                             board=args.board, dot_diameter=args.dot_diameter, mesh_source=args.mesh,
                             force=args.force, progress=not args.no_progress, fps=args.fps,
                             out_flag="--recording")
    report_recording(summary, rec, sys.stdout.write)
    return rec


def _run(args) -> int:
    from lipgen.recon.account import account_lines, missing_marks
    from lipgen.recon.crosscheck import tracking_lines
    from lipgen.recon.pipeline import reconstruct_dataset
    from lipgen.recon.restsource import check_rest_options, rest_line

    out = check_file_output(args.out, args.force)
    mesh_file = None if args.mesh.startswith("lip_mesh(") else args.mesh
    check_not_input(out, (args.dataset, mesh_file, args.rest_from, args.calib))
    check_rest_options(args.rest, args.rest_from)
    if args.rest_from is not None and not Path(args.rest_from).is_file():
        raise FileNotFoundError(f"--rest-from {args.rest_from}: no such file (a reconstruction written by "
                                "lipgen reconstruct --rest recording)")
    if args.rest_from is not None:  # its mesh and rest, before any work
        from lipgen.recon.pipeline import Reconstruction, model_mesh
        from lipgen.recon.restsource import check_rest_from

        check_rest_from(Reconstruction.load(args.rest_from), model_mesh(args.mesh), args.rest_from)
    from lipgen.recon.settings import ReconstructSettings

    given = {} if args.anchor_step is None else {"anchor_step": args.anchor_step or None}
    if args.no_cross_check:
        given["cross_check"] = False
    settings = ReconstructSettings(**given)   # else the library's defaults
    dataset = _dataset_or_recording(args, out)
    recon = reconstruct_dataset(dataset, args.mesh, settings=settings, progress=not args.no_progress,
                                normalisation=args.normalisation, test_frames=args.test_frames,
                                reference_frames=args.reference_frames, rest=args.rest,
                                rest_from=args.rest_from)
    recon.save(out)
    account = recon.info["sightings"]
    sys.stderr.write("\n".join(account_lines(account)) + "\n")
    for line in tracking_lines(recon.info):
        sys.stderr.write(line + "\n")
    sys.stdout.write(f"reconstructed {len(recon.fields)} frames ({100 * account['accepted_share']:.1f}% of "
                     f"marker sightings accepted: seen in both views, rays agreeing; calibration "
                     f"{recon.calibration.rms['all']:.3f} px RMS; displacements from {rest_line(recon)})"
                     f" -> {out}\n")
    missing = missing_marks(account)
    if missing:
        sys.stderr.write(f"lipgen reconstruct: warning: {len(missing)} marker(s) never accepted in any "
                         f"frame: {', '.join(missing)}" + ("" if args.allow_missing else
                                                   " (exit status 3; pass --allow-missing to accept)") + "\n")
        return 0 if args.allow_missing else MISSING_STATUS
    return 0
