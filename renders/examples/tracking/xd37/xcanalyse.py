"""Cross-check disputes vs the truth: per disputed frame-marker, is the first run right, the second, both wrong?
and what did the judge say (1 first, 2 second, 0 undecided -> kept first)."""
import sys, collections, numpy as np
from lipgen.evaluate.scoring import load_truth
from lipgen.dataset.layout import Dataset
c = collections.Counter(); spans = collections.Counter()
for name in sys.argv[1:]:
    try: d = np.load(f"/work/b37/xc/{name}.npz")
    except FileNotFoundError: continue
    if "disputed" not in d: continue
    t = load_truth(Dataset(f"/work/sets/{name}"))
    tuv = t["uv"].transpose(1, 0, 2, 3)        # (2, F, P, 2)
    ea = np.nanmax(np.linalg.norm(d["first"] - tuv, axis=-1), axis=0)    # worst view
    eb = np.nanmax(np.linalg.norm(d["second"] - tuv, axis=-1), axis=0)
    dis, ver = d["disputed"], d["verdict"]
    for f, p in zip(*np.nonzero(dis)):
        a_ok, b_ok = ea[f, p] <= 3, eb[f, p] <= 3
        truth = "first" if a_ok and not b_ok else "second" if b_ok and not a_ok else "both ok" if a_ok else "both wrong"
        c[(int(ver[f, p]), truth)] += 1
print("verdict (1 first, 2 second, 0 undecided->first), which run was right: count")
for k in sorted(c): print(k, c[k])
# score of policies over the disputed pairs (pairs, not sightings: x2 views)
def val(ok): return 1 if ok else -10
