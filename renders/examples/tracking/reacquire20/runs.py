"""New over-3px runs in r1 vs main: marker, view, frames, on whose true dot."""
import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
name, path, tag = sys.argv[1], sys.argv[2], sys.argv[3]
ds = Dataset(path); tr = load_truth(ds); names = list(ds.marks)
R = {t: Reconstruction.load(f"/work/reacq2/{name}.{t}.npz") for t in ("main", tag)}
E = {t: sighting_errors(tr, r) for t, r in R.items()}
for t in R:
    ok = E[t]["real"]["ok"]; w = sum(int((E[t][v]["ok"] & (E[t][v]["err"] <= 3)).sum()) for v in E[t])
    o = sum(int((E[t][v]["ok"] & (E[t][v]["err"] > 3)).sum()) for v in E[t]); print(t, "within", w, "over", o, "score", w - 10 * o)
for v, view in enumerate(("virtual", "real")):
    for t in R:
        e = E[t][view]; bad = e["ok"] & (e["err"] > 3)
        for p in np.flatnonzero(bad.any(0)):
            fr = np.flatnonzero(bad[:, p])
            # whose dot: nearest true mark to the tracked position
            F0 = fr[0]; u = R[t].uv[v, F0, p]; d = np.linalg.norm(tr["uv"][F0, v] - u, axis=1)
            prevlost = [int((R[t].status[v, max(0, F0 - k):F0, p] == 3).all()) for k in (1, 3)]
            print(f"  {t} {view} {names[p]}: {len(fr)} frames {fr[0]}-{fr[-1]}, first on {names[int(np.argmin(d))]} ({d.min():.1f} px), lost just before {prevlost}")
