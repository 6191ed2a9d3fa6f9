import sys
import numpy as np
sys.path.insert(0, "/work/corner19")
from offline import *  # noqa
from lipgen.recon.stereo_init import _similarity_3d
from lipgen.rig.pinhole import triangulate
mesh = model_mesh("lip_mesh(0)"); rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose]); names = [*mesh.marker_names, "nose"]
ci, li = names.index("corner_left"), names.index("lower_corner_left")
cr, lr = names.index("corner_right"), names.index("lower_corner_right")
for name in sys.argv[1:]:
    ds = Dataset(DATA / name); cal = calibration(name, ds); T = lab_frame(cal)
    lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3]); tu = load_truth(ds)["uv"]
    dl, dr, oy = [], [], []
    for t in range(tu.shape[0]):
        X = triangulate(lab.views[1], tu[t, 1], lab.views[0], tu[t, 0])[0]
        dl.append(np.linalg.norm(X[ci] - X[li])); dr.append(np.linalg.norm(X[cr] - X[lr]))
    print(f"{name:10s} |corner_left - lower_corner_left| median {np.nanmedian(dl):.2f} min {np.nanmin(dl):.2f};  right pair {np.nanmedian(dr):.2f} min {np.nanmin(dr):.2f}  (model 4.96)")
