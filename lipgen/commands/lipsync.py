"""``lipgen lipsync``: animate the lips from speech (audio and/or text) to USD(Z), npz or CSV."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

_EPILOG = """\
examples:
  lipgen lipsync speech.wav --text "The birch canoe slid on the smooth planks." --out canoe.usda
  lipgen lipsync speech.wav --out speech.usdc                 (no transcript: phone recognition)
  lipgen lipsync speech.wav --text-file words.txt --out lips.usdz       (one file, audio inside)
  lipgen lipsync speech.wav --text-file words.txt --model model.npz --fps 24 --out curves.csv
  lipgen lipsync --text "Glue the sheet to the dark blue background." --out glue.npz   (text alone)

From audio, the phones and their timings come from PocketSphinx (its en-US model ships in the
pocketsphinx wheel): forced alignment with a transcript, phone recognition without one. A
transcript that does not fit the audio is reported with its alignment confidence, and the
phones then come from recognition (a warning says so). Any common WAV rate and sample format
is read (mono mix, resampled to 16 kHz). From text alone, the phones come from the CMU
dictionary with Klatt's duration rules.

Phones become visemes (MPEG-4 classes), and visemes become activations of the synthetic
subject's muscle-like actions through critically damped dynamics (coarticulation); the
subject's motion is projected onto the modes of --model (a `lipgen train` model.npz of the
procedural lips) or of the default lips (10 modes of lip_mesh(0)).

Outputs: .usda/.usdc/.usd hold the blend-shape animation (as `lipgen export-usd` writes it) and,
from audio, a UsdMedia.SpatialAudio prim playing the WAV from frame 0; .npz holds the
coefficient and activation curves and the phones; .csv the coefficient curves; .usdz packages
the USD stage with the WAV inside, as one file. Nothing is written when the command fails, and
an existing --out is kept unless --force.
"""


def add_parser(sub) -> None:
    p = sub.add_parser("lipsync", help="animate the lips from speech audio and/or text (USD with audio, "
                       "npz, csv)", description="Lip sync: speech -> phones (PocketSphinx) -> visemes -> "
                       "muscle-like activations -> mode coefficients.", epilog=_EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("speech", nargs="?", help="speech recording (.wav); omit for text alone")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--text", help="English transcript of the speech (or the text to animate)")
    src.add_argument("--text-file", help="file holding the transcript (UTF-8)")
    p.add_argument("--model", help="fitted ModeModel (.npz, `lipgen train`); default: the default lips")
    p.add_argument("--fps", type=float, default=30.0, help="frames per second (default 30)")
    p.add_argument("--start", type=int, default=0, help="USD time code of the first frame (default 0)")
    p.add_argument("--rate", type=float, default=1.0, help="speaking-rate factor for text alone (default 1)")
    p.add_argument("--seed", type=int, default=0, help="seed of the synthetic subject (default 0)")
    p.add_argument("--weight-range", choices=("signed", "unit"), default="signed",
                   help="USD blend-shape weights in standard deviations (signed) or in [0, 1] (unit)")
    p.add_argument("--out", required=True, help="output: .usda, .usdc, .usd, .usdz, .npz or .csv")
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    p.set_defaults(func=_run)


def _text(args) -> str | None:
    if args.text_file:
        path = Path(args.text_file)
        if not path.is_file():
            raise FileNotFoundError(f"transcript file not found: {path}")
        try:
            return path.read_text(encoding="utf-8")
        except UnicodeDecodeError as exc:
            raise ValueError(f"{path} is not UTF-8 text ({exc})") from exc
    return args.text


def _run(args) -> int:
    from lipgen.commands._output import check_file_output, check_not_input
    from lipgen.speech.audio import read_wav
    from lipgen.speech.lipsync import lipsync, model_mesh, model_resolution
    from lipgen.speech.outputs import check_output, write_lipsync

    out = check_output(args.out, args.force)  # before any work
    check_file_output(out, args.force)  # and, as every command: not a folder, a writable folder
    check_not_input(out, (args.speech, args.model, args.text_file))
    from lipgen.usd.export import check_start

    check_start(args.start)
    text = _text(args)
    if args.speech is None and text is None:
        raise ValueError("give a speech recording (SPEECH.wav), a transcript (--text / --text-file), or both")
    if args.speech is not None and args.rate != 1.0:  # as lipsync() does, before the audio is read
        raise ValueError(f"--rate {args.rate} sets the pace of text alone; with a speech recording the "
                         "timing comes from the audio: drop --rate (or the recording)")
    model = None
    if args.model:
        from lipgen.modes.model import ModeModel

        model = ModeModel.load(args.model)
    audio = read_wav(args.speech) if args.speech else None
    result = lipsync(audio, text, model=model, fps=args.fps, seed=args.seed, rate=args.rate)
    mesh = None
    if out.suffix.lower() in (".usda", ".usdc", ".usd", ".usdz"):
        mesh = model_mesh(model_resolution(result.model))
    write_lipsync(out, result, mesh=mesh, wav=args.speech, start=args.start, force=args.force,
                  weight_range=args.weight_range)
    ph = result.phones
    how = {"alignment": f"aligned to the transcript (confidence {ph.confidence:.2f})",
           "recognition": "recognised (no usable transcript)", "text": "from the text (Klatt durations)"}
    sys.stdout.write(f"wrote {out}: {result.n_frames} frames at {result.fps:g} fps, "
                     f"{sum(p != 'SIL' for p in ph.labels)} phones {how[ph.source]}\n")
    return 0
