"""Mirror misses of markers seen before in the mirror (direct right): dot response at the truth; peak there?"""
import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
from lipgen.recon.dots import ink_gray, dot_response, DotSettings
allv = []
for name in sys.argv[1:]:
    ds = Dataset(f"/work/sets/{name}"); t = load_truth(ds)
    r = Reconstruction.load(f"/work/b37/rec/{name}.N.npz")
    sig = r.info["settings"]["tracker"]["dots"]["sigma"]
    e = sighting_errors(t, r); V, R = e["virtual"], e["real"]
    everV = np.cumsum(V["got"], axis=0) > 0
    miss = V["truly"] & ~V["got"] & R["got"] & (R["err"] <= 3) & np.vstack([np.zeros((1, V["got"].shape[1]), bool), everV[:-1]])
    for f in np.flatnonzero(miss.any(1)):
        g = ink_gray(ds.rig.split_views(np.asarray(ds[f].image))[0]); resp = dot_response(g, DotSettings(sigma=sig))
        for m in np.flatnonzero(miss[f]):
            u, v = t["uv"][f, 0, m]; c, rr = int(round(u)), int(round(v))
            win = resp[rr-2:rr+3, c-2:c+3]
            allv.append((win.max(), name, f, m))
vals = np.array([a[0] for a in allv])
print(len(vals), "response at truth: pct", np.percentile(vals, [10, 25, 50, 75, 90]).round(3), "share <0.03 %.2f, 0.03-0.05 %.2f, 0.05-0.08 %.2f, >=0.08 %.2f" % ((vals < 0.03).mean(), ((vals >= 0.03) & (vals < 0.05)).mean(), ((vals >= 0.05) & (vals < 0.08)).mean(), (vals >= 0.08).mean()))
import collections
c = collections.Counter((a[1], a[3]) for a in allv if a[0] >= 0.08)
print(c.most_common(15))
