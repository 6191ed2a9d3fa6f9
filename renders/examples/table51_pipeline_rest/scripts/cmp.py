import sys, numpy as np, logging
logging.disable(logging.WARNING)
sys.path.insert(0, '/work/wt/rest')
from pathlib import Path
from lipgen.recon.pipeline import Reconstruction, model_mesh
from lipgen.fem import Physics
from lipgen.recon.rest import metric_renormalize, measured_markers, rest_frames_near
W = Path('/work/t51val/work')
for seed in range(100, 118):
    r = Reconstruction.load(W / f"s{seed}_train.recon.npz")
    phys = Physics(model_mesh(r.info["mesh_source"])); mesh = phys.mesh; M = mesh.vertices[mesh.markers]
    n, _ = metric_renormalize(r, phys, rest=M)
    X = n.markers; m = measured_markers(n) & np.isfinite(X).all(-1)
    d2 = np.where(m, np.sum((X - M) ** 2, -1), np.nan)
    d = np.sqrt(np.nanmean(d2, 1))
    e = np.sort(np.argsort(np.nan_to_num(d, nan=np.inf))[:11])
    new = rest_frames_near(X, m, M)
    if not np.array_equal(e, new): print(seed, e.tolist(), new.tolist(), m.sum(1)[np.setdiff1d(e, new)])
