import sys, json, numpy as np
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
for l in open(sys.argv[1]):
    r = json.loads(l)
    if r["variant"] != "B" or not r.get("shared"): continue
    s = r["set"]
    try: m = Reconstruction.load(f"/work/b37/rec/{s}.main.npz")
    except FileNotFoundError: print(s, "no main rec"); continue
    names = list(m.info["marker_names"]) + ["nose"]
    e = sighting_errors(load_truth(Dataset(f"/work/sets/{s}")), m)
    for sp in r["shared"]:
        (i, j), (a, b) = sp["markers"], sp["frames"]
        ei = np.nanmax([e[v]["err"][a:b, i] for v in e]); ej = np.nanmax([e[v]["err"][a:b, j] for v in e])
        print(s, names[i], names[j], f"{a}-{b - 1}", "maxerr %.1f %.1f" % (ei, ej), "one wrong" if min(ei, ej) <= 3 < max(ei, ej) else "CHECK")
