"""How s47's swap of upper_corner_right in frames 0-1 of hard 213 (spent; truth read) reaches upper_right's
run split: the split's inputs under W and C, upper_right's chains, and its error per frame.
usage: MEMO_DIR=/work/b40 trace213.py"""
import os, sys, numpy as np
sys.path[:0] = [os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "w39")]
import cached
import lipgen.recon.pipeline as pl
from lipgen.recon.settings import ReconstructSettings
orig, got = pl.take_back_disagreeing, {}
def spy(tracks, vis, expected, *a, **k):
    got["vis"] = vis.copy(); got["tracks"] = tracks; got["args"] = (tracks, vis, expected, a, k)
    out = orig(tracks, vis, expected, *a, **k); got["split"] = out[1]; return out
pl.take_back_disagreeing = spy
res = {}
for name, kw in (("W", {}), ("C", {"cross_check_continuity": True})):
    cached.use("hard213"); got.clear()
    rec = pl.reconstruct_dataset("/work/sets/hard213", settings=ReconstructSettings(**kw))
    res[name] = dict(got); res[name]["gap"] = rec.info["ray_gap_limit_mm"]
print("limits", res["W"]["gap"], res["C"]["gap"])
vw, vc = res["W"]["vis"], res["C"]["vis"]
print("vis shape", vw.shape, "differs at", np.argwhere(vw != vc).tolist()[:40])
for v in range(2):
    d = np.linalg.norm(res["W"]["tracks"][v].uv - res["C"]["tracks"][v].uv, axis=-1)
    print("view", v, "uv differs at", np.argwhere(~((d < 1e-9) | (np.isnan(d)))).tolist()[:20])
print("split W", res["W"]["split"]); print("split C", res["C"]["split"])

import lipgen.recon.splitruns as sr
for name in "WC":
    tracks, vis, expected, a, k = res[name]["args"]
    jump, markers, names, ratio, spread = a
    # the chains, by the split's own grouping rule
    spacing = [sr.layout_spacing(expected[v][np.all(np.isfinite(expected[v]), axis=1)]) for v in range(2)]
    chains = []
    for f in np.flatnonzero(vis[:, 5]):
        best, bj = None, jump
        for c in chains:
            j = sr._jump(tracks, expected, spacing, vis, 5, c[-1], f, spread)
            if j <= bj:
                best, bj = c, j
        (chains.append([f]) if best is None else best.append(f))
    print(name, "chains of upper_right:", [[int(x) for x in c] for c in chains])
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
t = load_truth(Dataset("/work/sets/hard213")); tuv = np.moveaxis(t["uv"], 1, 0)
tracks = res["W"]["args"][0]
err = np.stack([np.linalg.norm(tracks[v].uv[:, 5] - tuv[v, :, 5], axis=-1) for v in range(2)])
print("upper_right error per frame (max over views):", np.round(np.nanmax(err, axis=0), 1).tolist())
