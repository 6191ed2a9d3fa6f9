"""Accepted sighting pairs (i, j) within R px of each other in BOTH views, same frame: how many are right/wrong."""
import sys, collections, numpy as np
from lipgen.evaluate.scoring import load_truth, sighting_errors, accepted_sightings
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
R = float(sys.argv[1]); c = collections.Counter(); truec = collections.Counter()
for arg in sys.argv[2:]:
    s, path = arg.split("=")
    tr = load_truth(Dataset(f"/work/sets/{s}")); rec = Reconstruction.load(path)
    e = sighting_errors(tr, rec); acc = accepted_sightings(rec)
    F, P1 = acc.shape
    # truth: pairs both visible in both views within R px in both views
    tuv = tr["uv"]; vis = np.asarray(tr["visible"], bool)
    for f in range(F):
        for i in range(P1):
            for j in range(i + 1, P1):
                if vis[f, :, i].all() and vis[f, :, j].all():
                    dd = np.linalg.norm(tuv[f, :, i] - tuv[f, :, j], axis=-1)
                    if (dd < R).all(): truec["true_close_both"] += 1
                    elif (dd < R).any(): truec["true_close_one"] += 1
                if acc[f, i] and acc[f, j]:
                    dd = np.linalg.norm(rec.uv[:, f, i] - rec.uv[:, f, j], axis=-1)
                    if (dd < R).all():
                        ei = max(e[v]["err"][f, i] for v in e); ej = max(e[v]["err"][f, j] for v in e)
                        c[("both_ok" if ei < 3 and ej < 3 else "one_wrong" if min(ei, ej) < 3 else "both_wrong")] += 1
print("R", R, dict(c), dict(truec))
