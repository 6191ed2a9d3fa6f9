"""``lipgen generate``: render a synthetic camera-mirror dataset with ground truth."""

from __future__ import annotations

import argparse
import sys

_EPILOG = """\
The folder gets manifest.json, mesh.npz, raw/NNNNNN.png (the camera-mirror frames), truth/NNNNNN.npz
(vertices, head pose, activations, 3-D marks and their projections and visibility in both views)
and calib/ (a chessboard in known poses, to calibrate the rig from images); with --depth also
depth/NNNNNN.npz (per-pixel camera depth, mm) and with --masks masks/NNNNNN.png (per-pixel labels:
skin, vermilion, mouth, each ink dot; legend in the manifest). The same settings
give the same bytes. A run that was stopped continues with --resume; a folder holding anything
else is never overwritten.

examples:
  lipgen generate --frames 150 --seed 0 --script "AA:0.3 EE:0.2 OO M:0.15 F REST:0.4" --out data/s0
  lipgen generate --frames 150 --seed 1 --out data/s1 --workers 2
  lipgen generate --frames 150 --seed 1 --out data/s1 --workers 2 --resume
  lipgen generate --frames 30 --depth --masks --out data/s2
  lipgen generate --frames 150 --preset hard --out data/hard0
  lipgen generate --frames 150 --preset default --video h264 --video-crf 20 --out data/v0

presets (image conditions; lipgen.dataset.presets): easy = today's ideal frames (pinhole, fixed
light, 1 grey level of noise, PNG; the default); default = a good laboratory recording; hard = an
ordinary camera: lens distortion, defocus, motion blur, light/exposure/white balance varying per
seed, a real mirror (tint, ghost, edge), shot and read noise, Bayer demosaicing, JPEG 85.
--video also writes video.mp4 (H.264 of the raw frames, in order) beside the PNGs.
"""


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 640x480, got {text!r}") from None
    return w, h


def add_parser(sub) -> None:
    p = sub.add_parser(
        "generate", help="render a synthetic camera-mirror dataset with ground truth",
        description="Simulate the synthetic subject (muscle-like actions on a finer lip model, jaw, "
        "head motion), film it in the camera-mirror rig and write raw frames with their ground truth.",
        epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    opt = p.add_argument
    opt("--out", required=True, help="dataset folder (new or empty; or the same dataset with --resume)")
    opt("--frames", type=int, default=150, help="number of frames (default 150)")
    opt("--seed", type=int, default=0, help="seed of every random choice (default 0)")
    opt("--script", default=None,
        help='viseme script, e.g. "AA:0.3 EE OO M F" (NAME or NAME:SECONDS, repeated to fill the '
        "frames); smooth random activations if omitted")
    opt("--size", type=_size, default=(640, 480), help="image size WxH, 4:3 (default 640x480)")
    opt("--workers", type=int, default=1, help="local rendering processes (default 1)")
    opt("--resume", action="store_true", help="continue an interrupted dataset with the same settings")
    opt("--fps", type=float, default=30.0, help="frame rate (default 30)")
    opt("--calib-frames", type=int, default=10, help="chessboard calibration frames (default 10)")
    opt("--preset", default="easy", choices=["easy", "default", "hard"],
        help="image conditions: lens, light, mirror, sensor (default easy: today's ideal frames)")
    opt("--video", default=None, metavar="CODEC",
        help="also deliver the frames as one video, video.mp4 (codec: h264)")
    opt("--video-crf", type=int, default=None, help="video quality, x264 CRF 0 (lossless)..51 (default 18)")
    opt("--noise", type=float, default=None,
        help="extra Gaussian noise, grey levels std (default: 1 with --preset easy, else 0)")
    opt("--head-rotation", type=float, default=4.0, help="head rotation range, degrees (default 4)")
    opt("--head-translation", type=float, default=4.0, help="head translation range, mm (default 4)")
    opt("--subject-resolution", type=int, default=1, help="truth mesh resolution (default 1)")
    opt("--dot-diameter", type=float, default=2.0, help="ink dot diameter, mm (default 2)")
    opt("--depth", action="store_true", help="also write each frame's depth image (depth/NNNNNN.npz)")
    opt("--masks", action="store_true", help="also write each frame's label mask (masks/NNNNNN.png)")
    opt("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from dataclasses import replace

    from lipgen.dataset.generate import generate
    from lipgen.dataset.presets import preset_settings

    extra = {} if args.noise is None else {"noise": args.noise}
    if args.video is not None or args.video_crf is not None:
        cond = preset_settings(args.preset).conditions
        extra["conditions"] = replace(cond, video_codec=args.video or "h264",
                                      video_crf=18 if args.video_crf is None else args.video_crf)
    settings = preset_settings(
        args.preset, frames=args.frames, seed=args.seed, script=args.script, size=args.size, fps=args.fps,
        subject_resolution=args.subject_resolution, head_rotation_deg=args.head_rotation,
        head_translation_mm=args.head_translation, dot_diameter=args.dot_diameter,
        calib_frames=args.calib_frames, depth=args.depth, masks=args.masks, **extra)
    out = generate(args.out, settings, workers=args.workers, resume=args.resume,
                   progress=not args.no_progress)
    sys.stdout.write(f"wrote {out} ({settings.frames} frames, {settings.calib_frames} calibration frames)\n")
    return 0
