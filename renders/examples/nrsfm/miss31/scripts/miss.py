import sys, time, json, numpy as np
from lipgen.nrsfm import reconstruct
from lipgen.nrsfm.metrics import e3d
from lipgen.nrsfm.validation import human_sequence
from lipgen.experiments.nrsfm_benchmarks import hide_points
for s in map(int, sys.argv[1:]):
    seq = human_sequence(s, 80); F, P = seq.W.shape[0] // 2, seq.W.shape[1]
    row = dict(name=seq.name)
    for kind in ("none", "random", "gaps"):
        vis = None if kind == "none" else hide_points(F, P, kind)
        W = seq.W.copy()
        if vis is not None:
            W[np.repeat(~vis, 2, axis=0)] = np.nan
        t = time.process_time(); rec = reconstruct(W, "auto", visible=vis); c = time.process_time() - t
        row[kind] = round(c, 2); row[kind + "_e"] = round(e3d(S_est=rec.S, S_true=seq.S), 3)
    row["ratio_random"] = round(row["random"] / row["none"], 2); row["ratio_gaps"] = round(row["gaps"] / row["none"], 2)
    print(json.dumps(row), flush=True)
