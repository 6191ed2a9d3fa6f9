"""``lipgen experiment``: the thesis's experiments on synthetic ground truth."""

from __future__ import annotations

import argparse
import sys
import textwrap

from lipgen.commands._output import add_force, check_folder_output


def add_parser(sub) -> None:
    p = sub.add_parser(
        "experiment",
        help="run an experiment of the thesis on synthetic truth and write its report",
        description="Run one of the thesis's experiments on synthetic ground truth.",
    )
    exp = p.add_subparsers(dest="experiment", metavar="EXPERIMENT")
    t = exp.add_parser(
        "table51",
        help="Table 5.1: LLSE reconstruction error from partial observations",
        description="Thesis Table 5.1 on a synthetic subject: 150 frames of random lip gestures, "
        "train learned modes on frames 1-140 from the 16 markers only (least-strain field per "
        "frame), and reconstruct the last 10 from 8 points (xyz), y-z or x-y views with 10 modes, "
        "the full sample covariance, the physics alone and the combined model. Errors are given "
        "against the thesis's reference (the least-strain field) and the true surface, in mm² and "
        "thesis units². Also: variance captured, error against the number of modes, and motions "
        "outside the training span. Writes report.md, table51.json and pictures to --out.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    t.add_argument("--out", default="renders/table51", help="output folder")
    t.add_argument("--seed", type=int, default=0, help="seed of the subject, gestures and head motion")
    t.add_argument("--frames", type=int, default=150, help="frames simulated")
    t.add_argument("--train", type=int, default=140, help="frames used for training (the rest test)")
    t.add_argument("--modes", type=int, default=10, help="modes kept")
    t.add_argument("--noise-mm", type=float, nargs="+", default=[0.0, 0.3],
                   help="marker measurement noise (std per coordinate, mm); one report section per value")
    t.add_argument("--truth-resolution", type=int, default=1, help="lip_mesh resolution of the truth (>= 1)")
    t.add_argument("--no-head", action="store_true", help="no head motion")
    add_force(t, "the report files in --out")
    t.add_argument("--preset", default="easy", choices=("easy", "default", "hard"),
                   help="subject conditions: easy (the model's shape, dots on its nodes, linear truth), "
                   "default (the subject's own shape and dots), hard (and nonlinear tissue; slow)")
    t.add_argument("--subject-seed", type=int, default=None,
                   help="seed of the subject's shape and dots (presets default and hard)")
    t.set_defaults(func=_table51)
    sp = exp.add_parser(
        "table51-splits",
        help="Table 5.1 trained on one utterance, tested on another utterance and another subject",
        description="For each subject seed: train 10 modes and the combined model on 140 frames of "
        "one utterance, then reconstruct --windows windows of 10 consecutive frames of other utterances of "
        "the same subject and of another subject (seed + 1000). Reports the error per hidden DOF "
        "(mm² and relative to the test motion) of 10 modes, the full covariance, the combined model "
        "and the physics, with the mean and a 95 % interval over the seeds, the x-y/y-z order, "
        "whether the estimators' intervals separate, and a paired comparison (each pair's error ratio "
        "over the same seeds and frames). Writes splits.md and splits.json to --out.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    sp.add_argument("--out", default="renders/table51_splits", help="output folder")
    sp.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4], help="subject seeds (2 or more)")
    sp.add_argument("--preset", default="default", choices=("easy", "default", "hard"),
                    help="subject and motion conditions (lipgen.dataset.presets)")
    sp.add_argument("--noise-mm", type=float, default=0.0, help="marker noise (std per coordinate, mm)")
    sp.add_argument("--noise-px", type=float, default=0.0,
                    help="marker pixel noise in both views of the camera-mirror rig, triangulated (std, px)")
    sp.add_argument("--windows", type=int, default=3,
                    help="test windows (10 consecutive frames, each its own utterance) per split and seed")
    add_force(sp, "the report files in --out")
    sp.set_defaults(func=_splits)
    pp = exp.add_parser(
        "table51-pipeline",
        help="Table 5.1 splits from rendered frames: generate, reconstruct, train, score",
        description="For each subject seed: render (preset default, pyrender) --frames frames of one "
        "utterance, --test-frames of another utterance of the same subject and of another subject "
        "(subject seed + 1000); reconstruct each (calibrate, track, triangulate, normalise); train 10 modes "
        "and the combined model on the first; score the Table 5.1 rows of lipgen evaluate on windows of 10 "
        "consecutive test frames against the true surface. Reports the mean and a 95 % interval over the "
        "seeds, the paired comparison and the x-y/y-z order, as table51-splits (given --splits, its "
        "splits.json on simulated markers is shown beside). Writes pipeline.md and pipeline.json to --out; "
        "the datasets and reconstructions go to --work (reused by a second run). "
        "Example: lipgen experiment table51-pipeline --seeds 0 1 2 3 4 --out renders/t51p",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    pp.add_argument("--out", default="renders/table51_pipeline", help="output folder")
    pp.add_argument("--work", default=None,
                    help="folder for the datasets and reconstructions (default: WORK under --out)")
    pp.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4], help="subject seeds (2 or more)")
    pp.add_argument("--frames", type=int, default=150, help="training frames rendered per seed")
    pp.add_argument("--test-frames", type=int, default=40, help="frames rendered per test utterance")
    pp.add_argument("--lead-in", type=int, default=10, help="test frames skipped at the start (rest pose)")
    pp.add_argument("--size", type=int, nargs=2, default=[640, 480], metavar=("W", "H"), help="image size")
    pp.add_argument("--workers", type=int, default=1, help="rendering processes")
    pp.add_argument("--splits", default=None, metavar="JSON",
                    help="splits.json of lipgen experiment table51-splits, shown beside")
    pp.add_argument("--utterance-reference", choices=("train", "own"), default="train",
                    help="normalisation reference of the utterance split's test recording: the training "
                         "recording's (one subject, one frame of reference) or its own most neutral frame")
    pp.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_force(pp, "the report files in --out")
    pp.set_defaults(func=_pipeline)
    tr = exp.add_parser(
        "tracking",
        help="the tracker against the truth over seeds: issue 15's targets (accepted share, RMS, > 3 px)",
        description=textwrap.fill(
        "For each seed: generate a dataset (--preset, --frames; kept in --work and reused by a second run "
        "with the same settings, never overwritten), reconstruct it as lipgen reconstruct does "
        "and score every sighting against the truth with lipgen evaluate's definitions. Or score existing "
        "datasets (--datasets). Reports per set and pooled: the accepted share of the visible sightings, "
        "the share within 3 px, the count over 3 px, RMS per view, tracking CPU per frame, issue 15's "
        "targets (RMS <= 0.5 px in each view, >= 97 % accepted, none > 3 px) met or not, and the mean "
        "and spread over the sets. Writes tracking.md, tracking.json and tracking.png to --out.", 100),
        formatter_class=argparse.RawDescriptionHelpFormatter, epilog="examples:\n"
        "  lipgen experiment tracking --preset hard --seeds 41 42 43 --out renders/tracking_exp\n"
        "  lipgen experiment tracking --datasets data/hard_s7 data/hard_s8 --out renders/tracking_78\n"
        "  # a quick check (minutes):\n"
        "  lipgen experiment tracking --preset easy --seeds 0 1 --frames 8 --out /tmp/quick",
    )
    tr.add_argument("--out", default="renders/tracking_exp",
                    help="output folder (default renders/tracking_exp)")
    tr.add_argument("--work", default=None,
                    help="folder for the generated datasets (reused by a later run with the same settings) "
                    "and the reconstructions LABEL.recon.npz (replaced only with --force); its parent must "
                    "exist (default: OUT/work)")
    src = tr.add_mutually_exclusive_group()
    src.add_argument("--seeds", type=int, nargs="+", default=None,
                     help="seeds of the generated sets (default 41 42 43)")
    src.add_argument("--datasets", nargs="+", default=None, metavar="PATH",
                     help="existing datasets (lipgen generate) to score instead of generating")
    tr.add_argument("--preset", default=None, help="preset of the generated sets: easy, default, hard "
                    "(default hard)")
    tr.add_argument("--frames", type=int, default=None, help="frames per generated set (default 40)")
    tr.add_argument("--size", type=int, nargs=2, default=None, metavar=("W", "H"),
                    help="image size of the generated sets (default 640 480)")
    tr.add_argument("--calib-frames", type=int, default=None,
                    help="chessboard frames of the generated sets (default: the preset's; hard: 40, the "
                    "last 30 of them lens frames). Given without --lens-frames it means no lens frames, "
                    "as in lipgen generate")
    tr.add_argument("--lens-frames", type=int, default=None,
                    help="of --calib-frames, how many show the lens board (default: the preset's with no "
                    "--calib-frames, else 0)")
    tr.add_argument("--note", default=None, help="a paragraph put under the report's title")
    tr.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_force(tr, "the report files in --out and the reconstructions in --work")
    tr.set_defaults(func=_tracking)
    n = exp.add_parser(
        "nrsfm",
        help="non-rigid SfM on the standard sequences (drink, jaws) beside the published e3D",
        description="Run every NRSfM method on drink and jaws (drink.npz and jaws.npz from --data, "
        "else $LIPGEN_NRSFM_DATA, else benchmarks/nrsfm in or beside the source tree) at the published Ks "
        "and at the K chosen from the "
        "reprojection curve ('em-ppca', whose K counts modes beyond the mean shape, at its own Ks), "
        "on the held-out validation set of synthetic human bodies (lipgen.nrsfm.validation) and on six "
        "held-out CMU motion-capture clips filmed twice each (lipgen.nrsfm.mocap), beside "
        "the flat zero-depth baseline; write benchmarks.md, benchmarks.json and the "
        "curves to --out. Takes minutes (two development bodies at 80 frames; the check of dai's "
        "automatic K against the flat baseline on fresh seeds 1400-1419, --check-seeds); --full runs eight "
        "bodies at 300 frames and the development seeds 300-310 and 400-410 at 300 and 80 frames (about an "
        "hour of CPU). Example: lipgen experiment nrsfm --sequences --no-synthetic --check-seeds 800 801 "
        "(the check alone).",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    n.add_argument("--out", default="renders/nrsfm", help="output folder")
    n.add_argument("--methods", nargs="+", default=["bregler", "dai", "dai-ba", "em-ppca"],
                   help="methods to run")
    n.add_argument("--data", default=None, metavar="DIR",
                   help="folder holding drink.npz and jaws.npz (default: $LIPGEN_NRSFM_DATA, else "
                   "benchmarks/nrsfm of the source tree)")
    n.add_argument("--no-synthetic", action="store_true",
                   help="skip the held-out validation set of synthetic human bodies")
    n.add_argument("--full", action="store_true",
                   help="the complete run: bodies 100-107 at 300 frames, check seeds at 300 and 80 frames")
    n.add_argument("--sequences", nargs="*", default=None, metavar="NAME",
                   help="standard sequences to run (default: drink jaws; none: skip them)")
    n.add_argument("--check-seeds", nargs="*", type=int, default=None, metavar="SEED",
                   help="seeds of the check of dai's automatic K against the flat baseline (80-frame "
                   "bodies; default 1400-1419, --full: 300-310 and 400-410; none: skip it)")
    n.add_argument("--mocap-clips", nargs="*", default=None, metavar="CLIP",
                   help="held-out CMU motion-capture clips to run every method on (lipgen.nrsfm.mocap; "
                   "default: all six; none: skip them)")
    add_force(n, "the report files in --out")
    n.set_defaults(func=_nrsfm)
    ls = exp.add_parser(
        "lipsync",
        help="lip-sync accuracy on Harvard sentences spoken by eSpeak NG (exact phone timings)",
        description="Synthesise Harvard sentences with eSpeak NG (apt-get install espeak-ng), whose "
        "phoneme events give the true phone timings; measure forced-alignment boundary errors, the "
        "phone error rate of recognition and the per-frame viseme agreement, clean and with "
        "speech-shaped noise; write report.md, lipsync.json and one picture per list to --out.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    ls.add_argument("--out", default="renders/lipsync", help="output folder")
    ls.add_argument("--lists", type=int, nargs="+", default=[1, 2],
                    help="Harvard lists (1-2: the test set; 3: the development set)")
    ls.add_argument("--snr", type=float, nargs="+", default=[float("inf"), 20.0, 10.0],
                    help="signal-to-noise ratios in dB (inf: clean)")
    ls.add_argument("--max-sentences", type=int, default=None, help="stop after this many sentences")
    add_force(ls, "the report files in --out")
    ls.set_defaults(func=_lipsync)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


def _lipsync(args) -> int:
    from lipgen.experiments.lipsync import LipsyncSettings, run_lipsync_experiment

    settings = LipsyncSettings(lists=tuple(args.lists), snr_db=tuple(args.snr),
                               max_sentences=args.max_sentences)
    check_folder_output(args.out, args.force, settings.report_files())
    sys.stdout.write(f"wrote {run_lipsync_experiment(args.out, settings)}\n")
    return 0


def _table51(args) -> int:
    from lipgen.experiments.table51 import Table51Settings, run_table51
    from lipgen.experiments.table51_report import report_files, write_report

    check_folder_output(args.out, args.force, report_files(args.noise_mm))
    every = [Table51Settings(n_frames=args.frames, n_train=args.train, n_modes=args.modes, seed=args.seed,
                             truth_resolution=args.truth_resolution, marker_noise_mm=noise,
                             head=not args.no_head, preset=args.preset, subject_seed=args.subject_seed)
             for noise in args.noise_mm]  # all checked before the first run
    runs = [run_table51(settings) for settings in every]
    report = write_report(runs, args.out)
    sys.stdout.write(f"wrote {report}\n")
    return 0


def _splits(args) -> int:
    from lipgen.experiments.table51_splits import SplitSettings, run_splits, write_splits_report

    settings = SplitSettings(seeds=tuple(args.seeds), preset=args.preset, marker_noise_mm=args.noise_mm,
                             n_windows=args.windows, marker_noise_px=args.noise_px)
    check_folder_output(args.out, args.force, ("splits.md", "splits.json"))
    sys.stdout.write(f"wrote {write_splits_report(run_splits(settings), args.out)}\n")
    return 0


def _pipeline(args) -> int:
    import json
    import os

    from lipgen.experiments.table51_pipeline import PipelineSettings, run_pipeline, write_pipeline_report

    settings = PipelineSettings(seeds=tuple(args.seeds), n_train=args.frames, n_test=args.test_frames,
                                lead_in=args.lead_in, size=tuple(args.size), workers=args.workers,
                                utterance_reference=args.utterance_reference)
    splits = None
    if args.splits is not None:
        if not os.path.isfile(args.splits):
            raise FileNotFoundError(f"--splits {args.splits} is not a file (splits.json of table51-splits)")
        try:
            with open(args.splits) as f:
                splits = json.load(f)
        except (UnicodeDecodeError, ValueError) as exc:
            raise ValueError(f"--splits {args.splits} is not JSON ({exc}); give splits.json of "
                             "table51-splits") from exc
    check_folder_output(args.out, args.force, ("pipeline.md", "pipeline.json"))
    if args.work is not None:  # a cache of datasets (resumed): may exist, but no folders made on the way
        check_folder_output(args.work, True, (), "--work")
    work = os.path.join(args.out, "work") if args.work is None else args.work
    result = run_pipeline(settings, work, progress=not args.no_progress)
    sys.stdout.write(f"wrote {write_pipeline_report(result, args.out, splits)}\n")
    return 0


def _nrsfm(args) -> int:
    from lipgen.experiments.nrsfm_benchmarks import NrsfmBenchSettings, run_nrsfm_benchmarks
    from lipgen.nrsfm import METHODS

    unknown = [m for m in args.methods if m not in METHODS]
    if unknown:
        raise ValueError(f"unknown method(s) {unknown}; choose from {sorted(METHODS)}")
    if args.data is not None:
        import os

        if not os.path.isdir(args.data):
            raise FileNotFoundError(f"--data {args.data} is not a folder (it holds drink.npz, jaws.npz)")
        os.environ["LIPGEN_NRSFM_DATA"] = args.data  # read by data_dir(), in this process only
    changes = {"methods": tuple(args.methods)} | ({"validation_seeds": ()} if args.no_synthetic else {})
    if args.sequences is not None:
        changes["sequences"] = tuple(args.sequences)
    if args.check_seeds is not None:
        changes["check_seeds"] = tuple(args.check_seeds)
    if args.mocap_clips is not None:
        from lipgen.nrsfm.mocap import CLIPS

        unknown = [c for c in args.mocap_clips if c not in CLIPS]
        if unknown:
            raise ValueError(f"unknown --mocap-clips {unknown}; the clips are {', '.join(CLIPS)}")
        changes["mocap_clips"] = tuple(args.mocap_clips)
    settings = NrsfmBenchSettings.full(**changes) if args.full else NrsfmBenchSettings(**changes)
    curves = tuple(f"{name}_curve.png" for name in settings.sequences)
    check_folder_output(args.out, args.force, ("benchmarks.md", "benchmarks.json", *curves))
    run_nrsfm_benchmarks(args.out, settings)
    sys.stdout.write(f"wrote {args.out}/benchmarks.md\n")
    return 0


def _tracking(args) -> int:
    from pathlib import Path

    from lipgen.experiments.tracking import run_tracking
    from lipgen.experiments.tracking_inputs import DEFAULT_SEEDS, TrackingSettings, check_inputs, recon_file
    from lipgen.experiments.tracking_report import REPORT_FILES, write_tracking_report

    if args.datasets is not None:
        given = [f for f, v in (("--preset", args.preset), ("--frames", args.frames), ("--size", args.size),
                                ("--calib-frames", args.calib_frames), ("--lens-frames", args.lens_frames))
                 if v is not None]
        if given:
            raise ValueError(f"{', '.join(given)} describe generated sets; with --datasets the sets are "
                             "as they were made (drop them)")
        settings = TrackingSettings(datasets=tuple(args.datasets))
    else:
        frames = 40 if args.frames is None else args.frames
        settings = TrackingSettings(preset=args.preset or "hard", frames=frames,
                                    seeds=tuple(args.seeds or DEFAULT_SEEDS),
                                    size=None if args.size is None else tuple(args.size),
                                    calib_frames=args.calib_frames, lens_frames=args.lens_frames)
    out = check_folder_output(args.out, args.force, REPORT_FILES)
    work = out / "work" if args.work is None else Path(args.work)
    plan = check_inputs(settings, work, force=args.force)  # before any work: a refused run writes nothing
    if args.work is not None or out.exists():  # else OUT/work is new inside a new OUT, checked above
        recons = [recon_file(work, label).name for label, _, _ in plan]
        check_folder_output(work, args.force, recons, "--work")
    out.mkdir(exist_ok=True)
    result = run_tracking(settings, work, progress=not args.no_progress, force=args.force, plan=plan)
    sys.stdout.write(f"wrote {write_tracking_report(result, out, args.note)}\n")
    return 0
