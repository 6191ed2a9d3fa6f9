import sys, numpy as np, logging
logging.disable(logging.WARNING)
sys.path.insert(0, sys.argv[1])
from pathlib import Path
import lipgen; assert lipgen.__file__.startswith(sys.argv[1]), lipgen.__file__
from lipgen.recon.pipeline import Reconstruction, model_mesh
from lipgen.fem import Physics
from lipgen.dataset.layout import Dataset
from lipgen.recon.rest import metric_renormalize
W = Path(sys.argv[2]); part = sys.argv[3]
out = []
for seed in map(int, sys.argv[4:]):
    r = Reconstruction.load(W / f"s{seed}_{part}.recon.npz"); ds = Dataset(W / f"s{seed}_{part}")
    phys = Physics(model_mesh(r.info["mesh_source"])); mesh = phys.mesh; P = len(mesh.markers)
    n, rest = metric_renormalize(r, phys)
    out.append(np.sqrt(np.mean(np.sum((rest - ds.rest_marks()[:P]) ** 2, -1))))
print(part, "mean %.2f median %.2f max %.2f >3mm %d" % (np.mean(out), np.median(out), np.max(out), np.sum(np.array(out) > 3)))
