import sys, numpy as np
from dataclasses import replace
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
from lipgen.recon.dots import detect_dots, DotSettings, ink_gray
from lipgen.recon.blobs import _pit_peaks
n = 0
for path in sys.argv[1:]:
    name = path.rstrip("/").split("/")[-1]
    ds = Dataset(path); t = load_truth(ds); rec = Reconstruction.load(f"/work/b35/rec/{name}.main.npz")
    names = list(ds.marks) + ["nose"]
    e = sighting_errors(t, rec)
    vis = e["virtual"]["truly"] & e["real"]["truly"]
    got = np.stack([rec.status[v] != 3 for v in range(2)])
    ok = e["virtual"]["ok"]
    lost = vis & ~got[0] & ~got[1]
    S = DotSettings(sigma=rec.info["settings"]["tracker"]["dots"]["sigma"])
    F = lost.shape[0]
    for f, i in zip(*np.nonzero(lost)):
        if 0 < f < F - 1 and ok[f - 1, i] and ok[f + 1, i]:
            rej = [bool(np.asarray(rec.info.get("x", 0)))]
            out = []
            for v in range(2):
                img = ds.rig.split_views(np.asarray(ds[f].image))[v]
                uv1, st = detect_dots(img, replace(S, min_contrast=0.05))
                r, c = _pit_peaks(ink_gray(img), S)
                tu = t["uv"][f, v, i]
                dd = np.linalg.norm(uv1 - tu, axis=1).min() if len(uv1) else 99
                dp = np.linalg.norm(np.column_stack([c, r]) - tu, axis=1).min() if len(r) else 99
                mid = 0.5 * (rec.uv[v][f - 1, i] + rec.uv[v][f + 1, i])
                out.append(f"v{v}: dot {dd:4.1f} pit {dp:4.1f} interp-err {np.linalg.norm(mid - tu):4.1f} speed {np.linalg.norm(rec.uv[v][f+1,i]-rec.uv[v][f-1,i])/2:4.1f}")
            print(name, names[i], f, " | ".join(out))
            n += 1
print(n)
