"""e3D of reconstruct(W, auto) and of W perturbed by 1e-14 (relative), per case; CPU of the first."""
import sys, time, json, numpy as np
from lipgen.nrsfm import reconstruct
from lipgen.nrsfm.metrics import e3d
from lipgen.nrsfm.validation import human_sequence
from lipgen.experiments.nrsfm_benchmarks import hide_points
out = open(sys.argv[1], "a")
for s in map(int, sys.argv[3:]):
    seq = human_sequence(s, 80); F, P = seq.W.shape[0] // 2, seq.W.shape[1]
    for kind in sys.argv[2].split(","):
        vis = hide_points(F, P, kind)
        row = dict(name=seq.name, kind=kind)
        for rep in (0, 1):
            W = seq.W * (1 + 1e-14 * np.random.default_rng(rep).standard_normal(seq.W.shape)) if rep else seq.W.copy()
            W[np.repeat(~vis, 2, axis=0)] = np.nan
            t = time.process_time(); rec = reconstruct(W, "auto", visible=vis); c = time.process_time() - t
            row[f"e{rep}"] = round(e3d(S_est=rec.S, S_true=seq.S), 4); row[f"k{rep}"] = int(rec.k); row[f"cpu{rep}"] = round(c, 2)
            row[f"sup{rep}"] = rec.depth_supported
        print(json.dumps(row), file=out, flush=True)
