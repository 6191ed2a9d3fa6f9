"""Leave-one-out layout prediction error of accepted markers, along each view's ray vs across (dev sets)."""
import sys, numpy as np
sys.path.insert(0, "/work/b35")
from ffh import setup
from lipgen.recon.pipeline import Reconstruction
from lipgen.recon.firstframe import predict_layout
from lipgen.recon.pointreg import layout_spacing
from lipgen.evaluate.scoring import accepted_sightings
import os
NOPHYS = os.environ.get("NOPHYS") == "1"
res = {0: [], 1: []}
for path in sys.argv[1:]:
    name = path.rstrip("/").split("/")[-1]
    g = setup(path); rec = Reconstruction.load(f"/work/b35/rec/{name}.main.npz")
    cams = g["cameras"]; rest = g["rest_points"]; cov = g["layout_covariance"]; width = layout_spacing(rest)
    acc = accepted_sightings(rec)
    for f in range(0, rec.lab_points.shape[0], 2):
        ok = acc[f].copy(); ok[-1] = ok[-1]
        if ok.sum() < 8:
            continue
        X = np.where(ok[:, None], rec.lab_points[f], 0.0)
        pred = predict_layout(rest, X, ok, width, None if NOPHYS else cov)
        for i in np.flatnonzero(ok[:-1]):
            e = rec.lab_points[f, i] - pred[i]
            for v in range(2):
                dirv = cams[v].rays(rec.uv[v][f, i][None])[1][0]
                a = abs(e @ dirv); p = np.sqrt(max(e @ e - a * a, 0))
                res[v].append((a, p))
for v in range(2):
    r = np.array(res[v])
    print("view", v, "n", len(r), "along median %.2f p90 %.2f | across median %.2f p90 %.2f | full median %.2f" % (
        np.median(r[:, 0]), np.percentile(r[:, 0], 90), np.median(r[:, 1]), np.percentile(r[:, 1], 90), np.median(np.hypot(r[:, 0], r[:, 1]))))
