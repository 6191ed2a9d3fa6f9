"""hard 102, frame 1: the motion check's view of lower_corner_left (14) in main and BHC2 (why the run taken
back in main passes with BHC2). usage: mc102.py SET MARKER main|BHC2"""
import sys
import numpy as np
from lipgen._threads import blas_threads
from lipgen.recon import motioncheck as MC
from lipgen.recon.dots import DotSettings
from lipgen.recon.pipeline import reconstruct_dataset
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.tracks import TrackerSettings
M = int(sys.argv[2])
orig = MC.MotionCheck._check
orig_pl = MC.predict_layout
calls = {}
def pl(model, X, use, spacing, cov):
    out = orig_pl(model, X, use, spacing, cov)
    calls["last"] = (X.copy(), use.copy(), out.copy())
    return out
def check(self, trackers, views, cameras, pts, k, resid, took, names, skipped):
    bad = orig(self, trackers, views, cameras, pts, k, resid, took, names, skipped)
    if k <= 2:
        X = pts[k]; both = np.isfinite(X[:, 0])
        print(f"frame {k}: both views {np.flatnonzero(both).tolist()}; established-ish use {calls['last'][1].sum()}; "
              f"resid[{M}]={resid[M]:.2f} mm, spacing {self.spacing:.2f}, median resid {np.nanmedian(resid):.2f}, "
              f"judged {self.judged[M]}, bad {bad}")
        print("   resid", np.round(resid, 1).tolist())
    return bad
MC.MotionCheck._check = check
MC.predict_layout = pl
bh = TrackerSettings(blobs=True, dots=DotSettings(blob_response="hessian"))
s = ReconstructSettings() if sys.argv[3] == "main" else ReconstructSettings(tracker=bh, confirm_blobs=True)
with blas_threads(1):
    reconstruct_dataset(sys.argv[1], settings=s)
