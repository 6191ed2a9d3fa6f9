import sys, numpy as np
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
var = sys.argv[1]
pool = {"vis": 0, "acc": 0, "over": 0, "err": {"virtual": [], "real": []}}
for s in sys.argv[2:]:
    e = sighting_errors(load_truth(Dataset(f"/work/sets/{s}")), Reconstruction.load(f"/work/b37/rec/{s}.{var}.npz"))
    vis = sum(int(v["truly"].sum()) for v in e.values()); acc = sum(int(v["ok"].sum()) for v in e.values())
    over = sum(int((v["err"][v["ok"]] > 3).sum()) for v in e.values())
    rms = {k: float(np.sqrt(np.mean(v["err"][v["ok"]] ** 2))) for k, v in e.items()}
    pool["vis"] += vis; pool["acc"] += acc; pool["over"] += over
    for k, v in e.items(): pool["err"][k] += list(v["err"][v["ok"]])
    print(s, f"accepted {100 * acc / vis:.1f} %, over 3 px {over}, RMS mirror {rms['virtual']:.2f} direct {rms['real']:.2f}")
print("pooled", f"accepted {100 * pool['acc'] / pool['vis']:.1f} %, over 3 px {pool['over']},", ", ".join(f"RMS {k} {np.sqrt(np.mean(np.square(v))):.2f}" for k, v in pool["err"].items()))
