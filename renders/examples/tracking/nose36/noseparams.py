"""The search's parameters from the truth of the development sets (all spent): how far the lips' similarity puts the
nose from the truth, the true nose's largest step and second difference per frame. Run from any folder with
PYTHONPATH at the tree; reads /work/sets."""
import numpy as np
from lipgen.evaluate.scoring import load_truth
from lipgen.dataset.layout import Dataset
from lipgen.recon.modelmesh import model_mesh
from lipgen.recon.nose import predict_nose

mesh = model_mesh()
rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose])
dev = [f"hard{s}" for s in (83, 85, 88, 90, 95, 96, 97, 98, 99, 100, 101, 102, 111, 112, 113, 114)]
dev += ["default160", "default161", "default162"]
med, mx, st, acc = [], [], [], []
for s in dev:
    X = load_truth(Dataset(f"/work/sets/{s}"))["marks_world"]
    p = predict_nose(X[:, :-1], np.ones(X.shape[:2], bool)[:, :-1], rest)
    e = np.linalg.norm(p - X[:, -1], axis=1)
    med.append(np.median(e)), mx.append(e.max())
    n = X[:, -1]
    st.append(np.linalg.norm(np.diff(n, axis=0), axis=1).max())
    acc.append(np.linalg.norm(n[2:] - 2 * n[1:-1] + n[:-2], axis=1).max())
print(len(dev), "sets: prediction error median per set %.1f-%.1f mm, max %.1f; step max %.2f mm; second difference "
      "max %.3f mm" % (min(med), max(med), max(mx), max(st), max(acc)))
