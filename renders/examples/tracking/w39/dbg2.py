import sys, pickle, numpy as np
sys.path.insert(0, "/work/wt/w39")
from lipgen.dataset.layout import Dataset
import lipgen.recon.extend as ex
name = sys.argv[1]
g = pickle.load(open(f"/work/b39/grab_{name}.pkl", "rb"))
ds = Dataset(f"/work/sets/{name}")
orig = ex._pick
def pick(found, pred, uv_f, status_f, i, gate, ratio, held_r, dots):
    r = orig(found, pred, uv_f, status_f, i, gate, ratio, held_r, dots)
    if i in (2, 14):
        cand = found[0]; d = np.linalg.norm(cand - pred[i], axis=1); j = np.argsort(d)[:3]
        others = np.delete(np.arange(len(uv_f)), i)
        held = uv_f[others][(status_f[others] != 3) & np.all(np.isfinite(uv_f[others]), axis=1)]
        rivals = np.vstack([held, pred[others][np.all(np.isfinite(pred[others]), axis=1)]])
        print("i", i, "pred", pred[i].round(1), "d", d[j].round(2), "rival dist", np.linalg.norm(rivals - cand[j[0]], axis=1).min().round(2), "->", r)
    return r
ex._pick = pick
out, rec = ex.extend_tracks(g["tracks"], lambda f: ds.rig.split_views(np.asarray(ds[f].image)), g["cameras"], g["accepted"],
    g["reference"], g["dots"], g["floor"], g["max_gap"], g["gate"], sure=None, min_run=int(sys.argv[2]))
print(rec)
