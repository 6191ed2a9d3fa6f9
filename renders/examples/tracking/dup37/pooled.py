import sys, numpy as np, os
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
var = sys.argv[1]; fallback = sys.argv[2]
REC = os.environ.get("REC", "/work/b37/rec")   # the folder of SET.VARIANT.npz (g38: REC=/work/b38/rec)
vis = acc = over = 0; err = {"virtual": [], "real": []}
for s in sys.argv[3:]:
    p = f"{REC}/{s}.{var}.npz"
    if not os.path.exists(p): p = f"{REC}/{s}.{fallback}.npz"
    e = sighting_errors(load_truth(Dataset(f"/work/sets/{s}")), Reconstruction.load(p))
    for k, v in e.items():
        vis += int(v["truly"].sum()); acc += int(v["ok"].sum()); over += int((v["err"][v["ok"]] > 3).sum()); err[k] += list(v["err"][v["ok"]])
print(var, f"accepted {100 * acc / vis:.1f} % ({acc} of {vis}), over 3 px {over},", ", ".join(f"RMS {k} {np.sqrt(np.mean(np.square(v))):.2f}" for k, v in err.items()),
      "| without >3px: " + ", ".join(f"{k} {np.sqrt(np.mean(np.square([x for x in v if x <= 3]))):.2f}" for k, v in err.items()))
