import sys
import numpy as np
sys.path.insert(0, "/work/corner19")
from offline import *  # noqa
from lipgen.recon.stereo_init import _similarity_3d
from lipgen.rig.pinhole import triangulate
mesh = model_mesh("lip_mesh(0)"); rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose]); names = [*mesh.marker_names, "nose"]
offs = []
for name in sys.argv[1:]:
    ds = Dataset(DATA / name); cal = calibration(name, ds); T = lab_frame(cal)
    lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3]); tu = load_truth(ds)["uv"]
    X = triangulate(lab.views[1], tu[0, 1], lab.views[0], tu[0, 0])[0]
    ok = np.all(np.isfinite(X), axis=1)
    S = _similarity_3d(rest[ok], X[ok])
    back = np.linalg.solve(S[:3, :3], (X - S[:3, 3]).T).T
    offs.append(back - rest)
    print(name, str(ds.settings)[:0], "corner_left off", (back - rest)[2].round(1), "corner_right off", (back - rest)[3].round(1))
o = np.array(offs)
print("median offset over sets (model frame, mm):")
for n, v in zip(names, np.nanmedian(o, axis=0)): print(f"  {n:20s} {v.round(2)}")
