"""Ran on commit 7fc722e (shared_dots with the layout judge, before B). Apply shared_dots to saved reconstructions' final tracks; score the decisions against the truth."""
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
gain = 0
for arg in sys.argv[1:]:
    s, path = arg.split("=")
    rec = Reconstruction.load(path); tr = load_truth(Dataset(f"/work/sets/{s}"))
    e = sighting_errors(tr, rec)
    tracks = tuple(Tracks(rec.uv[v], rec.status[v] != 3, rec.status[v], rec.score[v]) for v in range(2))
    sig = rec.info["settings"]["tracker"]["dots"]["sigma"]
    with blas_threads(1):
        taken, spans = shared_dots(tracks, rec.lab_calibration.views, rest, sig, cov)
    for sp in spans:
        (i, j), (a, b) = sp["markers"], sp["frames"]
        wi = np.nanmax([e[v]["err"][a:b, i] for v in e]); wj = np.nanmax([e[v]["err"][a:b, j] for v in e])
        print(s, names[i], names[j], a, b, "owner", names[sp["owner"]] if sp["owner"] >= 0 else "-", "d %s" % (sp["distance"],), "maxerr %.1f %.1f" % (wi, wj))
    for v in e:
        ok = e[v]["ok"] & taken
        gain += int((e[v]["err"][ok] > 3).sum()) * 10 - int((e[v]["err"][ok] <= 3).sum())
print("score gain", gain)
