"""Ran on commit 7fc722e (shared_dots with the layout judge, before B). On main's final tracks: each shared span's gain (score) under judges: layout (shared_dots), both, continuity."""
import sys, numpy as np
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
from lipgen.recon.modelmesh import model_mesh
from lipgen.recon.tracks import Tracks
from lipgen.recon.shareddot import shared_dots
from lipgen.recon.layoutprior import physics_layout_covariance
from lipgen.fem import Physics
from lipgen._threads import blas_threads
mesh = model_mesh("lip_mesh(0)")
rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose])
with blas_threads(1):
    cov = physics_layout_covariance(Physics(mesh))
names = [*mesh.marker_names, "nose"]
G = {"layout": 0, "both": 0, "cont": 0, "oracle": 0}
def gain(e, a, b, m):
    g = 0
    for v in e:
        ok = e[v]["ok"][a:b, m]; err = e[v]["err"][a:b, m]
        g += 10 * int((ok & (err > 3)).sum()) - int((ok & (err <= 3)).sum())
    return g
def seen(uv): return np.all(np.isfinite(uv), axis=-1)
for arg in sys.argv[1:]:
    s, path = arg.split("=")
    rec = Reconstruction.load(path); e = sighting_errors(load_truth(Dataset(f"/work/sets/{s}")), rec)
    tracks = tuple(Tracks(rec.uv[v], rec.status[v] != 3, rec.status[v], rec.score[v]) for v in range(2))
    sig = rec.info["settings"]["tracker"]["dots"]["sigma"]
    with blas_threads(1):
        _, spans = shared_dots(tracks, rec.lab_calibration.views, rest, sig, cov)
    uv = rec.uv  # (2, F, P, 2)
    F = uv.shape[1]
    for sp in spans:
        (i, j), (a, b), o = sp["markers"], sp["frames"], sp["owner"]
        gi, gj = gain(e, a, b, i), gain(e, a, b, j)
        lay = (gj if o == i else gi if o == j else gi + gj)
        # continuity: who was on (near) the dot in the frame before / stays on it after
        def near(m, f_other, f_dot):
            if not (0 <= f_other < F): return None
            if not seen(uv[:, f_other, m]).all(): return np.inf
            return float(np.linalg.norm(uv[:, f_other, m] - uv[:, f_dot, i], axis=-1).max())
        votes = []
        for fo, fd in ((a - 1, a), (b, b - 1)):
            di, dj = near(i, fo, fd), near(j, fo, fd)
            if di is None: continue
            if di < 0.5 * dj: votes.append(i)
            elif dj < 0.5 * di: votes.append(j)
        owner = votes[0] if votes and all(v == votes[0] for v in votes) else -1
        cont = gj if owner == i else gi if owner == j else gi + gj
        orc = max(gi, gj, gi + gj)
        G["layout"] += lay; G["both"] += gi + gj; G["cont"] += cont; G["oracle"] += orc
        print(s, names[i], names[j], f"{a}-{b-1}", "layout", names[o] if o >= 0 else "-", "cont", names[owner] if owner >= 0 else "-", "votes", [names[v] for v in votes], "gains: layout %d both %d cont %d" % (lay, gi + gj, cont))
print(G)
