import sys, numpy as np, logging
logging.disable(logging.WARNING)
sys.path.insert(0, '/work/wt/rest')
from pathlib import Path
from lipgen.recon.pipeline import Reconstruction, model_mesh
from lipgen.fem import Physics
from lipgen.recon.rest import metric_renormalize, measured_markers, rest_frames_near
from lipgen.recon.restsource import pause_count
W = Path(sys.argv[1])
cnt = []
for seed in map(int, sys.argv[2:]):
    r = Reconstruction.load(W / f"s{seed}_train.recon.npz")
    phys = Physics(model_mesh(r.info["mesh_source"])); mesh = phys.mesh; M = mesh.vertices[mesh.markers]
    n, _ = metric_renormalize(r, phys, rest=M)
    q = rest_frames_near(n.markers, measured_markers(n), M)
    cnt.append(pause_count(q)); print(seed, q.tolist(), cnt[-1])
print("pauses >=2:", sum(c >= 2 for c in cnt), "of", len(cnt))
