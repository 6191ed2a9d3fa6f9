"""Frame F's dot peaks near one marker's truth and its accepted sighting, per view, with strength and roundness
(truth read). usage: lure0.py ROOT SET VARIANT MARKER F  (ROOT: the memo folder, /work/b43 here)"""
import sys, os, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from spent import spent
from lipgen.recon.dots import as_gray, dot_peaks
root, name, var, mk, f = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4], int(sys.argv[5])
d = spent(root, name, var)
ds, rec, st, tuv = d["ds"], d["rec"], d["dots"], d["tuv"]
i = rec.info["marker_names"].index(mk)
print("sigma", round(st.sigma, 2), "min_roundness", st.min_roundness)
views = ds.rig.split_views(np.asarray(ds[f].image))
for v in range(2):
    uv, s, r = dot_peaks(as_gray(views[v]), st)
    tru = tuv[v, f, i]
    acc = rec.uv[v, f, i]
    print(f"view {v}: truth {np.round(tru,1)} accepted {np.round(acc,1)}")
    # all markers' truth, to name whose dot each peak is
    allt = tuv[v, f]
    for k in np.argsort(np.linalg.norm(uv - tru, axis=1))[:6]:
        d = np.linalg.norm(allt - uv[k], axis=1); j = int(np.nanargmin(d))
        print(f"   peak {np.round(uv[k],1)} d_truth {np.linalg.norm(uv[k]-tru):5.1f} d_acc {np.linalg.norm(uv[k]-acc):5.1f}"
              f" strength {s[k]:.3f} round {r[k]:.2f} nearest true dot {rec.info['marker_names'][j]} {d[j]:.1f}")
