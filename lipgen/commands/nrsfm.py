"""``lipgen nrsfm``: non-rigid structure from motion on a tracks file."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from lipgen.commands._output import check_file_output

_DESCRIPTION = """\
Reconstruct non-rigid 3D shape from 2D tracks under orthography.

TRACKS.npz holds W (2F x P, rows u1, v1, u2, v2, ...) and optionally visible (F x P bool,
False where a point is not observed; W may hold NaN there). If it also holds S (3F x P
ground truth, as the benchmark files do), the e3D error is printed. TRACKS.npz may also be a
reconstruction from lipgen reconstruct (of a synthetic dataset or of a recording, no truth
needed): one view's tracks (--view) are used, made weak-perspective with the calibrated camera.

SHAPES.npz gets S (3F x P camera-frame shapes, rows x1, y1, z1, x2, ...), R (F x 3 x 3),
weights (F x K), basis (K x 3 x P) (K + 1 for em-ppca), translation (F x 2), method, k,
reprojection_rms.
Depth has a global sign ambiguity under orthography (a mirror image fits equally well).

Methods:
  dai      Dai, Li & He 2012 (default): rotations from one corrective triple, shapes of least
           trace norm that reproject exactly, cut to rank K. Fast.
  dai-ba   dai, then low-rank bundle adjustment (Levenberg-Marquardt on the reprojection
           error), kept only if its depth is neither deeper nor rougher than 1.5 times
           dai's; else dai's answer. Slower; exact on noise-free low-rank data, with missing points.
  em-ppca  Torresani, Hertzmann & Bregler 2008 (EM-Gaussian): a mean shape plus K Gaussian
           deformation modes, fitted by EM from a rigid start; handles missing points. Here
           K counts the modes BEYOND the mean shape, so em-ppca --k 2 has 3 basis shapes (the
           size of dai --k 3), and --k 0 is rigid; weights are F x (K+1), basis (K+1) x 3 x P.
  em-pnd   Lee, Cho & Oh 2013/2017 (Procrustean normal distribution): aligned shapes normal
           about a mean, deformations that can neither translate nor rotate it; fitted by EM
           from dai at K + 1 shapes, kept only if its depth stays plausible. K counts modes
           beyond the mean, as for em-ppca.
  bregler  Bregler, Hertzmann & Biermann 1999 as written (3x3 metric upgrade).

--k auto reconstructs for K = 1, 2, ... (up to --kmax). dai and dai-ba: among the Ks whose
rotations are smoothest in time (within 5% of the least roughness), the smallest K that explains
noise-free tracks exactly with K shapes, else the smallest; the roughness per K is printed and
plotted. dai then answers flat (zero depth) when the even and the odd frames alone give rotations
that disagree (the tracks do not determine the depth); it prints which.
em-pnd: the least Bayesian information criterion of its own likelihood among K = 0, 1, 2, 4, 8, 12
(modes; up to --kmax), printed.
bregler and em-ppca: the smallest K whose RMS reprojection error is at most --rtol of the RMS of
the centred tracks (else where the curve flattens); the curve is plotted (Bregler et al. Fig 2).
"""


METHOD_NAMES: tuple[str, ...] = ("bregler", "dai", "dai-ba", "em-pnd", "em-ppca")
DEFAULT_METHOD = "dai"
"""The choices of ``--method``, spelled out so that ``lipgen nrsfm --help`` need not import
:mod:`lipgen.nrsfm` (and scipy.optimize); a test checks they match ``lipgen.nrsfm.METHODS``."""


def add_parser(sub) -> None:
    p = sub.add_parser("nrsfm", help="non-rigid structure from motion: 2D tracks -> 3D shapes",
                       description=_DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("tracks", metavar="TRACKS.npz", help="tracks file (W, optional visible, optional S)")
    p.add_argument("--k", required=True, metavar="K",
                   help="number of basis shapes (em-ppca: deformation modes beyond the mean), or 'auto' "
                   "(see below)")
    p.add_argument("--method", default=DEFAULT_METHOD, choices=METHOD_NAMES,
                   help=f"reconstruction method (default {DEFAULT_METHOD})")
    p.add_argument("--out", required=True, metavar="SHAPES.npz", help="output file")
    p.add_argument("--plot", metavar="CURVE.png",
                   help="write the reprojection curve here (default with --k auto: OUT stem + _curve.png; "
                   "for dai and dai-ba with --k auto: the rotation roughness per K)")
    p.add_argument("--kmax", type=int, default=None, help="largest K of the curve (default: what the "
                   "data allow, at most 15)")
    p.add_argument("--rtol", type=float, default=0.01,
                   help="--k auto: relative RMS reprojection error that counts as explained (default 0.01)")
    p.add_argument("--view", default="real", choices=("real", "virtual"),
                   help="with a reconstruction file: which view's tracks (default real)")
    p.add_argument("--seed", type=int, default=0, help="seed of the rotation search's random starts")
    p.add_argument("--force", action="store_true", help="overwrite OUT if it exists")
    p.set_defaults(func=_run)


def _parse_k(text: str):
    if text.strip().lower() == "auto":
        return "auto"
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"--k must be an integer (at least 1; at least 0 for em-ppca) or 'auto', "
                         f"got {text!r}") from None


def _recon_tracks(path, view, write) -> dict | None:
    """The tracks of one view if ``path`` is a reconstruction (lipgen reconstruct), else None."""
    import numpy as np

    try:
        with np.load(path, allow_pickle=False) as f:
            kind = str(f["__kind__"]) if "__kind__" in f.files else ""
    except (OSError, ValueError):
        return None
    if kind != "lipgen.Reconstruction":
        return None
    from lipgen.nrsfm.from_recon import reconstruction_tracks
    from lipgen.recon.pipeline import Reconstruction

    t = reconstruction_tracks(Reconstruction.load(path), view)
    write(f"reconstruction {path}: the {view} view's tracks, weak perspective at {t['depth']:.0f} mm\n")
    if t["dropped_marks"] or t["dropped_frames"]:
        write(f"left out: marks {t['dropped_marks']} (tracked in fewer than 3 frames), frames "
              f"{t['dropped_frames']} (fewer than 3 marks)\n")
    return t


def _run(args) -> int:
    from lipgen._threads import blas_threads
    from lipgen.commands._output import check_not_input, check_picture_output
    from lipgen.nrsfm import (
        MEAN_PLUS_MODES,
        e3d,
        load_tracks,
        plot_curve,
        reconstruct,
        reprojection_curve,
        save_shapes,
    )
    from lipgen.nrsfm.kchoice import SMOOTH_METHODS, reconstruct_auto
    from lipgen.nrsfm.metrics import plot_k_choice
    from lipgen.nrsfm.pndk import reconstruct_pnd_auto

    out = check_file_output(args.out, args.force)
    check_not_input(out, (args.tracks,))
    k = _parse_k(args.k)
    if args.seed < 0:
        raise ValueError(f"--seed must be a whole number >= 0, got {args.seed}")
    if args.kmax is not None and args.kmax < 1:
        raise ValueError(f"--kmax must be at least 1, got {args.kmax}")
    if not (0 < args.rtol < 1):  # also refuses nan
        raise ValueError(f"--rtol must be a number in (0, 1), got {args.rtol}")
    write = sys.stdout.write
    data = _recon_tracks(args.tracks, args.view, write) or load_tracks(args.tracks)
    W, visible = data["W"], data.get("visible")
    write(f"tracks: {W.shape[0] // 2} frames x {W.shape[1]} points"
          + (f", {int(visible.size - visible.sum())} unobserved" if visible is not None else "") + "\n")
    plot = args.plot or (str(out.with_name(out.stem + "_curve.png"))
                         if k == "auto" and args.method != "em-pnd" else None)  # em-pnd: a printed table
    if plot:
        check_picture_output(plot, args.force, "--plot")
        if Path(plot).resolve() == out.resolve():  # the shapes were written over the curve
            raise ValueError(f"--plot {plot} is --out too; give the picture and the shapes two names")
        check_not_input(plot, (args.tracks,), "--plot")
    rec = None
    if k == "auto" and args.method in SMOOTH_METHODS:
        t0 = time.perf_counter()
        rec = reconstruct_auto(W, args.method, visible, kmax=args.kmax or 15, seed=args.seed)
        seconds = time.perf_counter() - t0
        choice = rec.info["k_choice"]
        write("K   rotation roughness   exact K-shape fit\n")
        finished = choice.get("finished", [True] * len(choice["ks"]))
        unfinished = f"  (not finished: its {choice.get('unfinished', 'bound')})"
        for kk, rough, exact, done in zip(choice["ks"], choice["rotation_roughness"], choice["exact"],
                                          finished, strict=True):
            write(f"{kk:<3d} {rough:<20.4g} {'yes' if exact else 'no'}{'' if done else unfinished}\n")
        write(f"rule: {choice['rule']}\nchosen K = {rec.k}\n")
        if "depth_support" in rec.info:
            verdict = "kept" if rec.depth_supported else "dropped: the flat answer (zero depth)"
            write(f"depth {verdict} ({rec.info['depth_support']['reason']})\n")
        plot_k_choice(choice, plot)
        write(f"wrote {plot}\n")
    elif k == "auto" and args.method == "em-pnd":
        t0 = time.perf_counter()
        rec = reconstruct_pnd_auto(W, visible, kmax=args.kmax or 12, seed=args.seed)
        seconds = time.perf_counter() - t0
        choice = rec.info["k_choice"]
        write("K   BIC              plausible  exact\n")
        for kk, score, kept, exact in zip(choice["ks"], choice["bic"], choice["kept"], choice["exact"],
                                          strict=True):
            write(f"{kk:<3d} {score:<16.8g} {'yes' if kept else 'no':<10} {'yes' if exact else 'no'}\n")
        write(f"rule: {choice['rule']}\nchosen K = {rec.k}\n")
    elif k == "auto" or plot:
        first = 0 if args.method in MEAN_PLUS_MODES else 1
        ks = range(first, args.kmax + 1) if args.kmax is not None else None
        with blas_threads(1):
            curve = reprojection_curve(W, ks=ks, method=args.method, visible=visible, rtol=args.rtol,
                                       progress=True, seed=args.seed)
        write("K   RMS reprojection   % of track RMS\n")
        for kk, rms, rel in zip(curve.ks, curve.rms, curve.relative, strict=True):
            write(f"{kk:<3d} {rms:<18.4g} {100 * rel:.3g}\n")
        write(f"rule: {curve.rule}\n")
        if k == "auto":
            k = curve.chosen
            write(f"chosen K = {k}\n")
        plot_curve(curve, plot)
        write(f"wrote {plot}\n")
    if rec is None:
        t0 = time.perf_counter()
        with blas_threads(1):  # tracks are small: threads only wait on each other (lipgen._threads)
            rec = reconstruct(W, k, method=args.method, visible=visible, seed=args.seed)
        seconds = time.perf_counter() - t0
    save_shapes(out, rec)
    write(f"method {rec.method}, K = {rec.k}: RMS reprojection {rec.reprojection_rms:.4g} "
          f"({seconds:.2f} s)\n")
    if "S" in data:
        write(f"e3D against the S in {args.tracks}: {e3d(S_est=rec.S, S_true=data['S']):.4f}\n")
    write(f"wrote {out}\n")
    return 0
