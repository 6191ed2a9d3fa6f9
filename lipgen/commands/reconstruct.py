"""``lipgen reconstruct``: from a dataset's raw frames to displacement fields of the model."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

_EPILOG = """\
steps: calibrate the camera and the mirror from the dataset's chessboard frames; detect and track
the ink dots in both views (normalised correlation, first frame matched to the model's markers);
triangulate (closest point between rays); normalise (by default: the head rotation about the
nose that leaves the least force on the model, one scale from the most neutral frame; or the
thesis's section 3 lip planes with --normalisation thesis); and per frame the least-strain
field of the model reaching the markers (Physics.reach). The ground truth is not read.

examples:
  lipgen reconstruct data/s0 --out recon.npz
  lipgen reconstruct data/s0 --mesh my_lips.npz --out recon.npz
"""


def add_parser(sub) -> None:
    p = sub.add_parser("reconstruct", help="reconstruct displacement fields from a dataset's raw frames",
                       description="Calibrate, track, triangulate, normalise and reach: turn a dataset's raw "
                       "camera-mirror frames into per-frame displacement fields of the model mesh.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset", help="dataset folder written by lipgen generate")
    p.add_argument("--out", required=True, help="output file (.npz); an existing file is kept unless --force")
    p.add_argument("--mesh", default="lip_mesh(0)",
                   help="model mesh: 'lip_mesh(R)' (default lip_mesh(0)) or a LipMesh file (.npz)")
    p.add_argument("--normalisation", default="least-force",
                   choices=("thesis", "least-force", "least-strain", "procrustes"),
                   help="how the head pose is removed (default least-force; see lipgen.recon.normalize)")
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from lipgen.recon.pipeline import reconstruct_dataset

    out = Path(args.out)
    if out.exists() and not args.force:
        raise FileExistsError(f"{out} exists; choose another --out or pass --force to replace it")
    recon = reconstruct_dataset(args.dataset, args.mesh, progress=not args.no_progress,
                                normalisation=args.normalisation)
    recon.save(out)
    seen = 100 * recon.visible.mean()
    sys.stdout.write(f"reconstructed {len(recon.fields)} frames ({seen:.1f}% of marker sightings in both "
                     f"views, calibration {recon.calibration.rms['all']:.3f} px RMS) -> {out}\n")
    return 0
