import numpy as np
from lipgen.fem import Physics
from lipgen.recon.firstframe import predict_layout
from lipgen.recon.layoutprior import physics_layout_covariance
from lipgen.recon.lostneighbour import close_neighbours
from lipgen.recon.modelmesh import model_mesh
mesh = model_mesh("lip_mesh(0)"); rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose]); names = [*mesh.marker_names, "nose"]
cov = physics_layout_covariance(Physics(mesh)); near, judged, width = close_neighbours(rest)
for n, p in zip(names, rest): print(f"{n:20s} {p.round(2)}")
for a, b in [("lower_corner_left", "corner_left"), ("lower_corner_right", "corner_right"), ("upper_corner_left", "corner_left"), ("upper_corner_right", "corner_right")]:
    i, j = names.index(a), names.index(b)
    use = judged.copy(); use[[i, j]] = False
    pred = predict_layout(rest, np.where(use[:, None], rest, 0), use, width, cov)
    # a small rigid move + a pure mouth opening-like shift of the lower row
    print(a, b, "rest: pred err", np.linalg.norm(pred[i] - rest[i]).round(3), "d(i,j) rest", np.linalg.norm(rest[i]-rest[j]).round(2))
    d = cov[3*i:3*i+3, 3*i:3*i+3].diagonal(); e = cov[3*j:3*j+3, 3*j:3*j+3].diagonal()
    print("   prior var i", d.round(2), " j", e.round(2))
