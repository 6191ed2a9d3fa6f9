"""``lipgen generate``: render a synthetic camera-mirror dataset with ground truth."""

from __future__ import annotations

import argparse
import math
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
  lipgen generate --frames 150 --seed 1 --preset default --subject-seed 7 --out data/s1_subject7
  lipgen generate --frames 150 --seed 1 --out data/s1 --workers 2 --resume
  lipgen generate --frames 30 --depth --masks --out data/s2
  lipgen generate --speech speech.wav --text "The birch canoe slid on the smooth planks." --out data/s3
  lipgen generate --speech-text "Glue the sheet to the dark blue background." --out data/s4
  lipgen generate --frames 150 --preset hard --out data/hard0
  lipgen generate --frames 150 --preset default --video h264 --video-crf 20 --out data/v0
  lipgen generate --frames 10 --size 320x240 --renderer cycles --cycles-samples 16 --out data/c0

presets (image conditions; lipgen.dataset.presets): easy = today's ideal frames (pinhole, fixed
light, 1 grey level of noise, PNG; the default); default = a good laboratory recording; hard = an
ordinary camera: lens distortion, defocus, motion blur, light/exposure/white balance varying per
seed, a real mirror (tint, ghost, edge), shot and read noise, Bayer demosaicing, JPEG 85.
--video also writes video.mp4 (H.264 of the raw frames, in order) beside the PNGs.
--renderer cycles renders the same scene through the same cameras with Blender Cycles (the truth
is identical), recorded in the manifest with its samples.
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
    opt("--frames", type=int, default=None,
        help="number of frames (default 150, or as long as the speech with --speech/--speech-text)")
    opt("--seed", type=int, default=0, help="seed of the motion, head motion, noise and calibration "
        "(default 0)")
    opt("--preset", default="easy", choices=("easy", "default", "hard"),
        help="difficulty: easy (the model's shape, dots on its nodes, linear truth; as before presets), "
        "default (the subject's own shape and hand-placed dots), hard (and nonlinear tissue physics, "
        "about 0.06 s per frame; more head motion and noise). Default: easy. Flags below override the preset")
    opt("--subject-seed", type=int, default=None,
        help="seed of the subject's own lip shape and ink-dot placement (default: none, the model's "
        "shape with dots on its marker nodes)")
    opt("--script", default=None,
        help='viseme script, e.g. "AA:0.3 EE OO M F" (NAME or NAME:SECONDS, repeated to fill the '
        "frames); smooth random activations if omitted")
    opt("--speech", default=None, help="speech recording (.wav) that times the motion: its phones "
        "(PocketSphinx) -> visemes -> activations; the audio and phones are stored in speech/")
    opt("--text", default=None, help="transcript of --speech (forced alignment instead of recognition)")
    opt("--speech-text", default=None, help="English text spoken without audio (Klatt-rule durations)")
    opt("--size", type=_size, default=(640, 480), help="image size WxH, 4:3 (default 640x480)")
    opt("--workers", type=int, default=1, help="local rendering processes (default 1)")
    opt("--resume", action="store_true", help="continue an interrupted dataset with the same settings")
    opt("--fps", type=float, default=30.0, help="frame rate (default 30)")
    opt("--calib-frames", type=int, default=None,
        help="chessboard calibration frames (default 10; 40 with a distorted lens: default, hard)")
    opt("--lens-frames", type=int, default=None,
        help="how many of the calibration frames are lens frames, a large board filling one view "
        "(default 0; 30 with default and hard, unless --calib-frames is given)")
    opt("--video", default=None, metavar="CODEC",
        help="also deliver the frames as one video, video.mp4 (codec: h264)")
    opt("--video-crf", type=int, default=None, help="video quality, x264 CRF 0 (lossless)..51 (default 18)")
    opt("--noise", type=float, default=None,
        help="extra Gaussian noise, grey levels std (preset: 1 with easy, else 0: a sensor model instead)")
    opt("--head-rotation", type=float, default=None, help="head rotation range, degrees (preset: 4; hard 8)")
    opt("--head-translation", type=float, default=None, help="head translation range, mm (preset: 4; hard 6)")
    opt("--subject-resolution", type=int, default=1, help="truth mesh resolution (default 1)")
    opt("--dot-diameter", type=float, default=None, help="ink dot diameter, mm (preset: 2)")
    opt("--depth", action="store_true", help="also write each frame's depth image (depth/NNNNNN.npz)")
    opt("--masks", action="store_true", help="also write each frame's label mask (masks/NNNNNN.png)")
    opt("--renderer", default="pyrender", choices=("pyrender", "cycles"),
        help="pyrender (OpenGL, default) or cycles (Blender Cycles on the CPU: path tracing, subsurface "
        "scattering in skin and lips; needs pip bpy; much slower; --depth/--masks by pyrender). Same truth")
    opt("--cycles-samples", type=int, default=16, help="Cycles samples per pixel, denoised (default 16)")
    opt("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_run)


def _frames(args) -> int:
    """--frames, or enough frames for the speech (its phones' length at --fps)."""
    if args.frames is not None:
        return args.frames
    if args.speech:
        from lipgen.speech.audio import read_wav

        return int(math.ceil(read_wav(args.speech).duration * args.fps)) + 1
    if args.speech_text:
        from lipgen.speech.phones import text_phones

        return int(math.ceil(text_phones(args.speech_text).duration * args.fps)) + 1
    return 150


def _run(args) -> int:
    from dataclasses import replace

    from lipgen.commands._output import check_folder_output
    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import GenerateSettings

    check_folder_output(args.out, force=True)  # a new folder's parent exists: no folders made on the way
    for flag, words in (("--text", args.text), ("--speech-text", args.speech_text)):
        if words is not None and not words.strip():  # '' was taken as not given: random motion, recognition
            raise ValueError(f"{flag} is empty; give the words spoken")
    if args.text and not args.speech:
        raise ValueError("--text is the transcript of --speech; for text alone use --speech-text")
    if args.text and args.speech_text:
        raise ValueError("give the transcript once: --text (with --speech) or --speech-text")
    video = {}
    if args.video is not None or args.video_crf is not None:
        cond = GenerateSettings.from_preset(args.preset).conditions
        video["conditions"] = replace(cond, video_codec=args.video or "h264",
                                      video_crf=18 if args.video_crf is None else args.video_crf)
    settings = GenerateSettings.from_preset(
        args.preset, frames=_frames(args), seed=args.seed, script=args.script, size=args.size, fps=args.fps,
        speech=args.speech, speech_text=args.text or args.speech_text,
        subject_resolution=args.subject_resolution, head_rotation_deg=args.head_rotation,
        head_translation_mm=args.head_translation, noise=args.noise, dot_diameter=args.dot_diameter,
        calib_frames=args.calib_frames, lens_frames=args.lens_frames, depth=args.depth, masks=args.masks,
        subject_seed=args.subject_seed,
        renderer=args.renderer, cycles_samples=args.cycles_samples, **video)
    out = generate(args.out, settings, workers=args.workers, resume=args.resume,
                   progress=not args.no_progress)
    lens = f", {settings.lens_frames} of them lens frames" if settings.lens_frames else ""
    sys.stdout.write(f"wrote {out} ({settings.frames} frames, {settings.calib_frames} calibration "
                     f"frames{lens})\n")
    return 0
