"""curv22's candidates against main, one process per set (one calibration).

usage: python variants.py OUT.jsonl VARIANTS SET...   (from the repository's root, one BLAS thread)
VARIANTS, a comma list of:
  main  the defaults
  E     DotSettings(blob_response="hessian"): curvature blobs in the epipolar recovery   } apply
  B     TrackerSettings(blobs=True): the tracker's Laplacian blobs (main's code)        } hessian_blobs.patch
  BH    both of the above                                                                } first for E, BH,
  BHc   BH with blob_prediction=False, blob_share=0.5                                    } BHc
  J     lipgen.recon.grow.JOINT = True (apply joint_labels.patch first)
  C     lipgen.recon.firstpose.FIRST_FRAME_CAP = True (apply first_frame_cap.patch first)
Score per set: accepted within 3 px - 10 x accepted over 3 px (visible sightings, both views). Reconstructions
are saved as REC_DIR/SET.VARIANT.npz (REC_DIR: environment variable, default ./curv22_rec)."""
import json, os, sys
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from trackscore import run_and_score   # noqa: E402  (renders/examples/tracking/trackscore.py)
from lipgen.recon.dots import DotSettings
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.tracks import TrackerSettings


def settings_for(var):
    if var in ("J", "C"):
        import lipgen.recon.firstpose as firstpose
        import lipgen.recon.grow as grow
        grow.JOINT, firstpose.FIRST_FRAME_CAP = var == "J", var == "C"
    if var in ("main", "J", "C"):
        return ReconstructSettings()
    dots = DotSettings(blob_response="hessian") if var in ("E", "BH", "BHc") else DotSettings()
    extra = dict(blob_prediction=False, blob_share=0.5) if var == "BHc" else {}
    return ReconstructSettings(tracker=TrackerSettings(blobs=var != "E", dots=dots, **extra))


rec_dir = os.environ.get("REC_DIR", "curv22_rec")
os.makedirs(rec_dir, exist_ok=True)
out = open(sys.argv[1], "a")
for path in sys.argv[3:]:
    for var in sys.argv[2].split(","):
        name = os.path.basename(path.rstrip("/"))
        row = run_and_score(path, var, settings_for(var), os.path.join(rec_dir, f"{name}.{var}.npz"))
        print(json.dumps(row), file=out, flush=True)
