"""How far the markers move per frame in the direct view, and against the mean of all markers (truth; after the runs)."""
import numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
for s in ["default182", "default184", "default185", "hard207", "hard208", "hard209", "hard210", "hard199"]:
    t = load_truth(Dataset(f"/work/sets/{s}")); uv = t["uv"][:, 1, :16]
    step = np.diff(uv, axis=0)
    d = np.linalg.norm(step, axis=-1)
    dd = np.linalg.norm(step - step.mean(1, keepdims=True), axis=-1)
    print(s, len(uv), "step px p50 %.1f p99 %.1f max %.1f; step less the mean p99 %.1f max %.1f" % (
        np.median(d), np.percentile(d, 99), d.max(), np.percentile(dd, 99), dd.max()))
