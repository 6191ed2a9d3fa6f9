"""Per case: reconstruct(W, auto) on W and on two 1e-14 perturbations of it; e3D, K, support, CPU."""
import sys, time, json, numpy as np
from lipgen.nrsfm import reconstruct
from lipgen.nrsfm.metrics import e3d
from lipgen.nrsfm.validation import human_sequence
from lipgen.experiments.nrsfm_benchmarks import hide_points
out = open(sys.argv[1], "a")
for s in map(int, sys.argv[2:]):
    seq = human_sequence(s, 80); F, P = seq.W.shape[0] // 2, seq.W.shape[1]
    for kind in ("none", "random", "gaps"):
        vis = None if kind == "none" else hide_points(F, P, kind)
        for j in ((0,) if kind == "none" else (0, 1, 2)):
            W = seq.W * (1 + 1e-14 * np.random.default_rng(j).standard_normal(seq.W.shape)) if j else seq.W.copy()
            if vis is not None:
                W[np.repeat(~vis, 2, axis=0)] = np.nan
            t = time.process_time(); rec = reconstruct(W, "auto", visible=vis); c = time.process_time() - t
            print(json.dumps(dict(name=seq.name, kind=kind, draw=j, cpu=round(c, 2), k=int(rec.k),
                                  e=round(e3d(S_est=rec.S, S_true=seq.S), 4), supported=rec.depth_supported)),
                  file=out, flush=True)
