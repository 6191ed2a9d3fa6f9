import sys, time, json, numpy as np
from lipgen.nrsfm import reconstruct
from lipgen.nrsfm.metrics import e3d
from lipgen.nrsfm.validation import human_sequence
from lipgen.experiments.nrsfm_benchmarks import hide_points
out = open(sys.argv[1], "a")
for s in map(int, sys.argv[3:]):
    seq = human_sequence(s, 80); F, P = seq.W.shape[0] // 2, seq.W.shape[1]
    for kind in sys.argv[2].split(","):
        vis = None if kind == "none" else hide_points(F, P, kind)
        W = seq.W.copy()
        if vis is not None: W[np.repeat(~vis, 2, axis=0)] = np.nan
        t = time.process_time(); rec = reconstruct(W, "auto", visible=vis); c = time.process_time() - t
        ds = rec.info.get("depth_support", {})
        row = dict(name=seq.name, kind=kind, cpu=round(c, 2), k=int(rec.k), e=round(e3d(S_est=rec.S, S_true=seq.S), 4),
                   angle=None if ds.get("angle_deg") is None else round(float(ds["angle_deg"]), 2), supported=rec.depth_supported)
        print(json.dumps(row), file=out, flush=True)
