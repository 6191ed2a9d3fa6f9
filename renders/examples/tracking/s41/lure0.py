"""Frame F's dot peaks near one marker's truth and its accepted sighting, per view, with strength and roundness
(truth read; recs and calibration from /work/b43). usage: lure0.py SET MARKER F"""
import sys, pickle, numpy as np
from dataclasses import replace
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.pipeline import Reconstruction, dot_sigma_px, lab_frame
from lipgen.recon.dots import DotSettings, as_gray, dot_peaks
from lipgen.recon.settings import ReconstructSettings
name, mk, f = sys.argv[1], sys.argv[2], int(sys.argv[3])
ds = Dataset(f"/work/sets/{name}"); t = load_truth(ds)
rec = Reconstruction.load(f"/work/b43/rec/{name}.P2.npz")
i = rec.info["marker_names"].index(mk)
cal = pickle.load(open(f"/work/b43/cache/{name}.calib.pkl", "rb"))
sig = dot_sigma_px(cal, lab_frame(cal), float(ds.settings.dot_diameter))
st = replace(ReconstructSettings().tracker.dots, sigma=sig)
print("sigma", round(sig, 2), "min_roundness", st.min_roundness)
views = ds.rig.split_views(np.asarray(ds[f].image))
for v in range(2):
    uv, s, r = dot_peaks(as_gray(views[v]), st)
    tru = t["uv"][f, v, i] if t["uv"].shape[1] == 2 else t["uv"][v, f, i]
    acc = rec.uv[v, f, i]
    print(f"view {v}: truth {np.round(tru,1)} accepted {np.round(acc,1)}")
    # all markers' truth, to name whose dot each peak is
    allt = t["uv"][f, v] if t["uv"].shape[1] == 2 else t["uv"][v, f]
    for k in np.argsort(np.linalg.norm(uv - tru, axis=1))[:6]:
        d = np.linalg.norm(allt - uv[k], axis=1); j = int(np.nanargmin(d))
        print(f"   peak {np.round(uv[k],1)} d_truth {np.linalg.norm(uv[k]-tru):5.1f} d_acc {np.linalg.norm(uv[k]-acc):5.1f}"
              f" strength {s[k]:.3f} round {r[k]:.2f} nearest true dot {rec.info['marker_names'][j]} {d[j]:.1f}")
