"""Hidden-entry error against the truth: the whole sequence's completion at rank 3K (truth read, dev bodies)."""
import sys, json, numpy as np
from lipgen.nrsfm.completion import complete_subspace
from lipgen.nrsfm.validation import human_sequence
from lipgen.experiments.nrsfm_benchmarks import hide_points
out = []
for s in (1700, 1702, 1704, 1709, 1710):
    seq = human_sequence(s, 80); F, P = seq.W.shape[0] // 2, seq.W.shape[1]
    for kind in ("random", "gaps"):
        vis = hide_points(F, P, kind); hid = np.repeat(~vis, 2, axis=0)
        row = [s, kind]
        for K in (3, 6, 9):
            full = complete_subspace(seq.W, vis, 3 * K)[0]
            row.append(round(float(np.sqrt(((full - seq.W)[hid] ** 2).mean()) / seq.W.std()), 4))
        print(json.dumps(row), flush=True)
