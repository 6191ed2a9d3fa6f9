"""For accepted sightings i with a close neighbour j NOT seen in both views: distance of i's point to i's and j's
layout predictions (both from the other pairs, i left out). Does 'j explains it better' flag the wrong ones?"""
import sys, json, numpy as np
from lipgen.evaluate.scoring import load_truth, sighting_errors, accepted_sightings
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
from lipgen.recon.modelmesh import model_mesh
from lipgen.recon.layoutprior import physics_layout_covariance
from lipgen.recon.firstframe import predict_layout
from lipgen.recon.pointreg import layout_spacing
from lipgen.rig.pinhole import triangulate
from lipgen.fem import Physics
from lipgen._threads import blas_threads
mesh = model_mesh("lip_mesh(0)")
rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose])
with blas_threads(1):
    cov = physics_layout_covariance(Physics(mesh))
names = [*mesh.marker_names, "nose"]
width = layout_spacing(rest)
dist = np.linalg.norm(rest[:, None] - rest[None], axis=2); np.fill_diagonal(dist, np.inf)
out = open(sys.argv[1], "w")
for arg in sys.argv[2:]:
    s, path = arg.split("=")
    rec = Reconstruction.load(path); tr = load_truth(Dataset(f"/work/sets/{s}"))
    e = sighting_errors(tr, rec); acc = accepted_sightings(rec)
    cams = rec.lab_calibration.views
    F, P = acc.shape
    for f in range(F):
        use = acc[f].copy()
        X = np.full((P, 3), np.nan)
        X[use] = triangulate(cams[1], rec.uv[1, f, use], cams[0], rec.uv[0, f, use])[0]
        for i in np.flatnonzero(use):
            js = [j for j in range(P) if not acc[f, j] and dist[i, j] < 1.6 * width]
            if not js or use.sum() < 7: continue
            u = use.copy(); u[i] = False
            with blas_threads(1):
                pred = predict_layout(rest, X, u, width, cov)
            di = float(np.linalg.norm(X[i] - pred[i]))
            err = max(float(e[v]["err"][f, i]) for v in e)
            for j in js:
                dj = float(np.linalg.norm(X[i] - pred[j]))
                onj = max(float(np.linalg.norm(rec.uv[v, f, i] - tr["uv"][f, v, j])) for v in range(2))
                print(json.dumps({"set": s, "f": f, "i": names[i], "j": names[j], "di": round(di, 3), "dj": round(dj, 3),
                                  "err": round(err, 2), "onj": round(onj, 2)}), file=out, flush=True)
