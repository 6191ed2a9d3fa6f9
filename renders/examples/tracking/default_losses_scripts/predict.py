"""Replay carry_lost_markers on the recorded tracks to estimate where the tracker searched for lost markers."""
import pickle, collections
import numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.recon.association import carry_lost_markers
from lipgen.recon.dots import DotSettings, ink_gray, dot_peaks
SETS = [1, 2, 3, 4, 5, 100, 101, 102, 103, 104]
res = []
for n in SETS:
    d = pickle.load(open(f"/work/diagdef/data_default_{n}.pkl", "rb"))
    ds = Dataset(f"/work/deftrack/sets/default_{n}")
    st = DotSettings(sigma=d["sigma"])
    F, P1 = d["F"], d["P1"]
    lostset = {(r["f"], r["v"], r["p"]): r for r in d["rows"] if r["kind"] == "lost" and r["dmin"] <= 1.5}
    frames_needed = sorted({k[0] for k in lostset})
    preds = np.full((2, F, P1, 2), np.nan); gaps = np.zeros((2, F, P1), int)
    for v in range(2):
        uv, vis = d["uv"][v], d["status"][v] != 3
        last = np.where(vis[0][:, None], uv[0], np.nan); gap = np.zeros(P1, int)
        before = last.copy()
        for f in range(1, F):
            carry_lost_markers(last, before, uv[f-1], vis[f-1])
            preds[v, f] = last; gaps[v, f] = gap
            before = last.copy()
            last[vis[f]] = uv[f][vis[f]]
            gap[vis[f]] = 0; gap[~vis[f] & np.all(np.isfinite(last), axis=1)] += 1
    for f in frames_needed:
        halves = ds.rig.split_views(ds[f].image)
        for v in range(2):
            ks = [k for k in lostset if k[0] == f and k[1] == v]
            if not ks: continue
            pk, s, rnd = dot_peaks(ink_gray(halves[v]), st)
            pk = pk[rnd >= 0.3]
            for (_, _, p) in ks:
                t = d["tuv"][f, v, p]; pr = preds[v, f, p]
                dp = float(np.linalg.norm(pr - t)) if np.all(np.isfinite(pr)) else np.inf
                g = gaps[v, f, p]
                reach = 8 + 3 * min(g, 3)
                if np.isfinite(dp):
                    dd = np.linalg.norm(pk - pr, axis=1)
                    rivals = int((dd < dp - 0.5).sum())   # round dots nearer the prediction than the true dot
                    within = int((dd <= reach).sum())
                else:
                    rivals, within = -1, -1
                res.append(dict(set=n, f=f, v=v, p=p, name=d["names"][p], dpred=dp, gap=int(g), reach=reach,
                                rivals=rivals, within=within, taken=lostset[(f, v, p)]["taken"]))
    print(n, len(res), flush=True)
pickle.dump(res, open("/work/diagdef/pred.pkl", "wb"))
R = res
def cls(r):
    if not np.isfinite(r["dpred"]): return "never seen (no prediction)"
    if r["dpred"] > r["reach"]: return "prediction out of reach"
    if r["rivals"] > 0: return "in reach, nearer rival dot"
    return "in reach, nearest dot (gate/ratio/other)"
c = collections.Counter(cls(r) for r in R); print(c)
for n in SETS:
    print(n, collections.Counter(cls(r) for r in R if r["set"] == n))
dp = np.array([r["dpred"] for r in R if np.isfinite(r["dpred"])]); print("dpred pct 25/50/75/90", np.percentile(dp, [25, 50, 75, 90]))
print("gap median", np.median([r["gap"] for r in R]))
