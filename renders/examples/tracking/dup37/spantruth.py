"""For each span the candidate found, which marker was right (truth, from main's rec where both hold the dot),
and for N whether its owner was. usage: spantruth.py ROWS.jsonl CANDIDATE"""
import sys, json, numpy as np
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
rows = [json.loads(l) for l in open(sys.argv[1])]
for r in rows:
    if r["variant"] != sys.argv[2] or not r.get("shared"): continue
    s = r["set"]
    try: m = Reconstruction.load(f"/work/b37/rec/{s}.main.npz")
    except FileNotFoundError: print(s, "no main rec"); continue
    names = list(m.info["marker_names"]) + ["nose"]
    e = sighting_errors(load_truth(Dataset(f"/work/sets/{s}")), m)
    for sp in r["shared"]:
        (i, j), (a, b), o = sp["markers"], sp["frames"], sp.get("owner", -2)
        ei = np.nanmax([e[v]["err"][a:b, i] for v in e]); ej = np.nanmax([e[v]["err"][a:b, j] for v in e])
        right = i if ei <= 3 < ej else j if ej <= 3 < ei else ("both<=3" if max(ei, ej) <= 3 else "both>3")
        verdict = ("" if o == -2 else "right" if o == right else "neither kept" if o == -1 else "WRONG")
        print(s, names[i], names[j], f"{a}-{b - 1}", "owner", names[o] if o >= 0 else "-", "maxerr %.1f %.1f" % (ei, ej),
              "right: " + (names[right] if isinstance(right, int) else right), verdict)
