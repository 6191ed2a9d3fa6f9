import sys, numpy as np
sys.path.insert(0, '/work/main')
from pathlib import Path
from lipgen.recon.pipeline import Reconstruction, model_mesh
from lipgen.fem import Physics
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.rest import quiet_rest, measured_markers, metric_renormalize
W = Path('/work/t51p80/work')
for seed in map(int, sys.argv[1:]):
    r = Reconstruction.load(W / f"s{seed}_train.recon.npz")
    ds = Dataset(W / f"s{seed}_train")
    phys = Physics(model_mesh(r.info["mesh_source"]))
    mesh = phys.mesh; P = len(mesh.markers)
    n, rest = metric_renormalize(r, phys)
    tr = load_truth(ds)
    marks = tr["marks_model"][:, :P]; trest = ds.rest_marks()[:P]
    m = measured_markers(n)
    _, q = quiet_rest(n.markers, m, return_frames=True)
    tdisp = np.linalg.norm(marks - trest, axis=-1)  # F,P
    print(f"seed {seed}: F={len(marks)} rest frames {q.tolist()}")
    print("  true disp RMS at rest frames %.2f mm, over all frames %.2f" % (np.sqrt(np.mean(tdisp[q]**2)), np.sqrt(np.mean(tdisp**2))))
    # per-frame true disp RMS
    fr = np.sqrt(np.mean(tdisp**2, 1))
    print("  quietest true frames:", np.argsort(fr)[:10].tolist(), np.round(np.sort(fr)[:10], 2).tolist())
    err = rest - trest
    print("  rest - true rest RMS %.2f mm; per marker:" % np.sqrt(np.nanmean(np.sum(err**2, 1))), np.round(np.linalg.norm(err, axis=1), 1).tolist())
    # measured markers vs true marks per frame, offsets
    e = np.where(m[..., None], n.markers - marks, np.nan)
    off = np.nanmean(e, 0)
    print("  marker position mean error vs truth per marker RMS %.2f" % np.sqrt(np.nanmean(np.sum(off**2, 1))))
    print("  per-frame position error RMS at rest frames %.2f, all %.2f" % (np.sqrt(np.nanmean(np.sum(e[q]**2, -1))), np.sqrt(np.nanmean(np.sum(e**2, -1)))))
    print("  scale info", n.info["normalisation"].get("scale"), "accepted %.3f" % m.mean())
