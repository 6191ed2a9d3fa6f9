"""Jumps between a marker's consecutive accepted frames, against its neighbours' motion, labelled by the truth."""
import sys, pickle, numpy as np, collections
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.backfill import neighbour_motion
from lipgen.recon.pointreg import layout_spacing
rows = []
for name in sys.argv[1:]:
    g = pickle.load(open(f"/work/b40/gf_{name}.pkl", "rb"))
    t = load_truth(Dataset(f"/work/sets/{name}"))
    acc = g["accepted"]; F, P1 = acc.shape; P = P1 - 1
    uv = np.stack([g["tracks"][v].uv for v in range(2)])
    tuv = np.moveaxis(t["uv"], 1, 0)
    err = np.linalg.norm(uv - tuv, axis=-1)
    wrong = (err > 3).any(0)
    ref = g["reference"]
    for m in range(P):
        fr = np.flatnonzero(acc[:, m])
        for a, b in zip(fr[:-1], fr[1:]):
            both = acc[a] & acc[b]; both[P] = False
            j = []
            for v in range(2):
                mv = neighbour_motion(ref[v], uv[v, a], uv[v, b], both, m, layout_spacing(ref[v]))
                j.append(np.nan if mv is None else np.linalg.norm(uv[v, b, m] - uv[v, a, m] - mv))
            rows.append((name, m, a, b, j[0], j[1], wrong[a, m], wrong[b, m]))
import json
json.dump([[r[0], int(r[1]), int(r[2]), int(r[3]), float(r[4]), float(r[5]), bool(r[6]), bool(r[7])] for r in rows],
          open("/work/b40/jumps.json", "w"))
kind = collections.defaultdict(list)
for r in rows:
    kind[("W" if r[6] else "R") + ("W" if r[7] else "R")].append(min(r[4], r[5]))
for k, v in sorted(kind.items()):
    v = np.array(v); print(k, len(v), "min-view jump pct 50/90/99/max", np.nanpercentile(v, [50, 90, 99, 100]).round(1),
                          "n>4", int((v > 4).sum()), "n>6", int((v > 6).sum()))

# Runs split at jumps over J px (min of the views); each adjacent pair of runs that disagree: which is wrong?
from lipgen.recon.firstframe import predict_layout, triangulate_matched
from lipgen.recon.pointreg import layout_spacing as ls3
J = float(__import__("os").environ.get("J", 5))
for name in sys.argv[1:]:
    g = pickle.load(open(f"/work/b40/gf_{name}.pkl", "rb"))
    t = load_truth(Dataset(f"/work/sets/{name}"))
    acc = g["accepted"]; F, P1 = acc.shape; P = P1 - 1
    uv = np.stack([g["tracks"][v].uv for v in range(2)])
    err = np.linalg.norm(uv - np.moveaxis(t["uv"], 1, 0), axis=-1); wrong = (err > 3).any(0)
    rest = g["rest"]; cams = g["cameras"]
    R = np.full((F, P1), np.nan)
    for f in range(F):
        use = acc[f].copy(); use[P] = False
        if use.sum() < 6: continue
        X = triangulate_matched(cams, [uv[0, f], uv[1, f]], use)
        pred = predict_layout(rest, X, use, ls3(rest[:P]), g["cov"])
        R[f] = np.linalg.norm(X - pred, axis=1)
    mine = [r for r in rows if r[0] == name]
    for m in range(P):
        fr = np.flatnonzero(acc[:, m])
        if len(fr) < 2: continue
        cuts = [i + 1 for i, r in enumerate([r for r in mine if r[1] == m]) if min(r[4], r[5]) > J]
        runs = np.split(fr, cuts)
        for r1, r2 in zip(runs[:-1], runs[1:]):
            print(f"{name} {g['names'][m]:18s} run {r1[0]}-{r1[-1]} (n{len(r1)} wrong {int(wrong[r1, m].sum())} R {np.nanmean(R[r1, m]):.2f})"
                  f"  vs {r2[0]}-{r2[-1]} (n{len(r2)} wrong {int(wrong[r2, m].sum())} R {np.nanmean(R[r2, m]):.2f})")
