"""How the fill's sightings compare with the truth (development sets): filled pairs, right (both views <= 3 px)."""
import sys, os, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.pipeline import Reconstruction
var = os.environ.get("VAR", "GF")
tot = [0, 0, 0]
for path in sys.argv[1:]:
    name = path.rstrip("/").split("/")[-1]
    ds = Dataset(path); t = load_truth(ds)
    m = Reconstruction.load(f"/work/b35/rec/{name}.main.npz"); g = Reconstruction.load(f"/work/b35/rec/{name}.{var}.npz")
    changed = np.zeros(m.status.shape[1:], bool)
    for v in range(2):
        a, b = m.uv[v], g.uv[v]
        changed |= ~((np.isnan(a) & np.isnan(b)) | (a == b)).all(-1)
    err = np.stack([np.linalg.norm(g.uv[v] - t["uv"][:, v], axis=-1) for v in range(2)])
    right = changed & (err <= 3).all(0); wrong = changed & ~(err <= 3).all(0)
    print(name, g.info.get("gap_fill"), "changed pairs", int(changed.sum()), "right", int(right.sum()), "wrong", int(wrong.sum()))
    for f, i in zip(*np.nonzero(wrong)):
        fr = [(np.linalg.norm(m.uv[v][f + d, i] - t["uv"][f + d, v, i]) if 0 <= f + d < len(ds) else np.nan) for d in (-1, 1) for v in range(2)]
        print("   wrong fill", list(ds.marks)[i] if i < len(ds.marks) else "nose", "frame", f, "err", err[:, f, i].round(1), "framing errs (f-1 v0,v1; f+1 v0,v1)", np.round(fr, 1))
    tot[0] += int(changed.sum()); tot[1] += int(right.sum()); tot[2] += int(wrong.sum())
print("total changed/right/wrong", tot)
