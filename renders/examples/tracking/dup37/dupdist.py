import sys, numpy as np
from lipgen.evaluate.scoring import accepted_sightings
from lipgen.recon.pipeline import Reconstruction
ds = []
for arg in sys.argv[1:]:
    s, path = arg.split("="); rec = Reconstruction.load(path); acc = accepted_sightings(rec)
    F, P1 = acc.shape
    for f in range(F):
        for i in range(P1):
            for j in range(i + 1, P1):
                if acc[f, i] and acc[f, j]:
                    dd = np.linalg.norm(rec.uv[:, f, i] - rec.uv[:, f, j], axis=-1)
                    if dd.max() < 6: ds.append((dd.max(), s))
ds.sort(); print([("%.2f" % d, s) for d, s in ds[:5]], [("%.2f" % d, s) for d, s in ds[60:90]])
print("sep sigma:", Reconstruction.load(sys.argv[1].split("=")[1]).info["settings"]["tracker"]["dots"] if "settings" in Reconstruction.load(sys.argv[1].split("=")[1]).info else "")
