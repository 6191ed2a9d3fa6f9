"""Where the direct view holds a marker and the mirror does not (accepted nowhere): the mirror's dot response at
the truth, against the tracker's floor. usage: mirrorresp.py SET"""
import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
from lipgen.recon.dots import ink_gray, dot_response, DotSettings, darkness
name = sys.argv[1]
ds = Dataset(f"/work/sets/{name}"); t = load_truth(ds)
r = Reconstruction.load(f"/work/b37/rec/{name}.N.npz")
sig = r.info["settings"]["tracker"]["dots"]["sigma"]
e = sighting_errors(t, r)
miss = e["real"]["got"] & ~e["virtual"]["got"] & e["virtual"]["truly"]
vals = []; own = []
for f in np.flatnonzero(miss.any(1)):
    views = ds.rig.split_views(np.asarray(ds[f].image))
    g = ink_gray(views[0]); resp = dot_response(g, DotSettings(sigma=sig))
    for m in np.flatnonzero(miss[f]):
        u, v = t["uv"][f, 0, m]; c, rr = int(round(u)), int(round(v))
        vals.append(resp[rr-1:rr+2, c-1:c+2].max())
    okm = e["virtual"]["ok"][f] & ~miss[f]
    for m in np.flatnonzero(okm):
        u, v = t["uv"][f, 0, m]; c, rr = int(round(u)), int(round(v)); own.append(resp[rr-1:rr+2, c-1:c+2].max())
vals = np.array(vals); own = np.array(own)
print(name, "mirror misses (direct has it):", len(vals), "response median %.3f, share >= 0.05: %.2f, >= 0.03: %.2f" % (np.median(vals), (vals >= 0.05).mean(), (vals >= 0.03).mean()),
      "| accepted mirror dots: median %.3f p10 %.3f" % (np.median(own), np.percentile(own, 10)))
