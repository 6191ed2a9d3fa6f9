import sys, numpy as np, collections
from pathlib import Path
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.modelmesh import model_mesh
mesh = model_mesh("lip_mesh(0)")
names = [*mesh.marker_names, "nose"]
tot = collections.Counter(); starts = collections.Counter(); by_marker = collections.Counter()
for tag, s in [a.split(":") for a in sys.argv[1:]]:
    z = np.load(f"/work/hard18/out/{tag}/{s}.npz")
    tr = load_truth(Dataset(Path("/work/data") / s))
    uv, acc = z["uv"], z["accepted"]
    P = acc.shape[1]
    tuv = np.moveaxis(tr["uv"], 1, 0); vis = np.moveaxis(tr["visible"], 1, 0)
    err = np.linalg.norm(uv[:, :, :P] - tuv[:, :, :P], axis=-1)
    over = acc[None] & vis[:, :, :P] & (err > 3)
    for v, f, k in zip(*np.nonzero(over)):
        d = np.linalg.norm(tuv[v, f] - uv[v, f, k], axis=-1); d[k] = np.inf
        j = int(np.argmin(d))
        if d[j] < 2:
            cls = "neighbour's dot, neighbour accepted" if (j < P and acc[f, j]) else "neighbour's dot, neighbour not accepted"
        else:
            cls = "no dot within 2 px (lure)"
        tot[cls] += 1; by_marker[names[k]] += 1
    for k in range(P):
        fr = np.flatnonzero(over[:, :, k].any(0))
        if len(fr):
            first_acc = np.flatnonzero(acc[:, k])[0]
            starts["bad from its first accepted frame" if fr[0] == first_acc else "went bad later"] += over[:, :, k].sum()
print(dict(tot)); print(dict(starts)); print(by_marker.most_common(8))
