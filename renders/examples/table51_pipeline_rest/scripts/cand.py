"""Candidate truth-free rest rules on table51-pipeline training recordings: rest error vs the true rest."""
import sys, numpy as np, logging
logging.disable(logging.WARNING)
sys.path.insert(0, '/work/main')
from pathlib import Path
from lipgen.recon.pipeline import Reconstruction, model_mesh
from lipgen.fem import Physics
from lipgen.dataset.layout import Dataset
from lipgen.recon.rest import quiet_rest, measured_markers, metric_renormalize, quiet_frames, _densest_half

def rms_to(X, m, ref):
    """(F,) RMS distance of each frame's measured markers to ref (P,3)."""
    d2 = np.where(m, np.sum((X - ref) ** 2, -1), np.nan)
    return np.sqrt(np.nanmean(d2, 1))

def med(X, m, frames):
    out = np.full(X.shape[1:], np.nan)
    for j in range(X.shape[1]):
        f = frames[m[frames, j]]
        if len(f) >= 2: out[j] = np.median(X[f, j], 0)
    return out

def smooth_speed_frames(X, m, share, k=2):
    F = len(X)
    Xs = np.where(m[..., None], X, np.nan)
    pos = np.stack([np.nanmedian(Xs[max(0, f - k):f + k + 1], 0) for f in range(F)])
    mm = np.isfinite(pos).all(-1)
    return quiet_frames(np.nan_to_num(pos), mm, share)

def cands(X, m, M):
    F = len(X); out = {}
    share = max(0.15, 10 / F)
    q = quiet_frames(X, m, share)
    out["A densest"] = med(X, m, _densest_half(X, m, q))
    d = rms_to(X, m, M)
    out["B nearest-model half"] = med(X, m, np.sort(q[np.argsort(d[q])[:(len(q) + 1) // 2]]))
    q3 = quiet_frames(X, m, max(0.3, 10 / F))
    out["B2 nearest-model half s.3"] = med(X, m, np.sort(q3[np.argsort(d[q3])[:(len(q) + 1) // 2]]))
    qs = smooth_speed_frames(X, m, share)
    out["C smooth densest"] = med(X, m, _densest_half(X, m, qs))
    # D: neighbourhoods (half of q around each quiet frame); the one whose median is nearest the model rest
    k = (len(q) + 1) // 2
    best, bd = None, np.inf
    for i in q:
        D = rms_to(X[q], m[q] & m[i], X[i])
        nb = np.sort(q[np.argsort(np.nan_to_num(D, nan=np.inf))[:k]])
        r = med(X, m, nb)
        dd = np.sqrt(np.nanmean(np.sum((r - M) ** 2, -1)))
        if dd < bd: bd, best = dd, r
    out["D cluster nearest model"] = best
    kk = (len(q) + 1) // 2
    out["E nearest-model any"] = med(X, m, np.sort(np.argsort(np.nan_to_num(d, nan=np.inf))[:kk]))
    near2 = np.sort(np.argsort(np.nan_to_num(d, nan=np.inf))[:len(q)])
    out["I densest half of 2k nearest model"] = med(X, m, _densest_half(X, m, near2))
    near3 = np.sort(np.argsort(np.nan_to_num(d, nan=np.inf))[:int(1.5 * len(q))])
    out["I3 densest third of 3k nearest model"] = med(X, m, _densest_half(X, m, near3)[:0] if False else np.sort(near3[np.argsort(np.nanmean(np.array([rms_to(X[near3], m[near3] & m[i], X[i]) for i in near3]), 0))[:kk]]))
    r = out["E nearest-model any"]
    for it in range(10):
        rr = np.where(np.isfinite(r), r, M)
        sel = np.sort(np.argsort(np.nan_to_num(rms_to(X, m, rr), nan=np.inf))[:kk])
        r = med(X, m, sel)
    out["E2 mean-shift from model"] = r
    q3 = quiet_frames(X, m, max(0.3, 10 / F)); k3 = (len(q3) + 1) // 2
    best, bd = None, np.inf
    for i in q3:
        D = rms_to(X[q3], m[q3] & m[i], X[i])
        nb = np.sort(q3[np.argsort(np.nan_to_num(D, nan=np.inf))[:kk]])
        r = med(X, m, nb)
        dd = np.sqrt(np.nanmean(np.sum((r - M) ** 2, -1)))
        if dd < bd: bd, best = dd, r
    out["F cluster nearest model s.3"] = best
    for w in (2, 3):
        still = np.full(F, np.inf)
        Xn = np.where(m[..., None], X, np.nan)
        for f in range(w, F - w):
            win = Xn[f - w:f + w + 1]
            cnt = np.isfinite(win[..., 0]).sum(0)
            okj = cnt >= w + 1
            if okj.sum() < 3: continue
            c = np.nanmedian(win[:, okj], 0)
            dev = np.sqrt(np.nanmean(np.sum((win[:, okj] - c) ** 2, -1), 0))
            still[f] = np.median(dev)
        qg = np.sort(np.argsort(still, kind="stable")[:len(q)])
        out[f"G still w{w} densest"] = med(X, m, _densest_half(X, m, qg))
        b = int(np.argmin(still))
        out[f"H stillest window w{w}"] = med(X, m, np.arange(b - w, b + w + 1))
    out["model"] = M.copy()
    return out

W = Path(sys.argv[1]); part = sys.argv[2]; seeds = [int(s) for s in sys.argv[3:]]
res = {}
for seed in seeds:
    f = W / f"s{seed}_{part}.recon.npz"
    if not f.is_file(): continue
    r = Reconstruction.load(f); ds = Dataset(W / f"s{seed}_{part}")
    phys = Physics(model_mesh(r.info["mesh_source"])); mesh = phys.mesh; P = len(mesh.markers)
    M = mesh.vertices[mesh.markers]
    n, _ = metric_renormalize(r, phys, rest=M)
    X = n.markers; m = measured_markers(n) & np.isfinite(X).all(-1)
    trest = ds.rest_marks()[:P]
    cc = cands(X, m, M)
    from lipgen.evaluate.scoring import load_truth
    tm = load_truth(ds)["marks_model"][:, :P]
    td = np.sqrt(np.mean(np.sum((tm - trest) ** 2, -1), 1))
    cc["ORACLE true-quietest 10 (diagnostic)"] = med(X, m, np.sort(np.argsort(td)[:10]))
    for name, rest in cc.items():
        rest = np.where(np.isfinite(rest), rest, M)
        res.setdefault(name, []).append(np.sqrt(np.mean(np.sum((rest - trest) ** 2, -1))))
    print(seed, " ".join("%.2f" % res[k][-1] for k in res), flush=True)
print("seeds", len(res["model"]))
for k, v in res.items():
    v = np.array(v)
    print(f"{k:28s} mean {v.mean():.2f} median {np.median(v):.2f} max {v.max():.2f} >3mm {np.sum(v > 3)}")
