import sys, os, numpy as np
VAR = os.environ.get('VAR', 'main')
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
for path in sys.argv[1:]:
    name = path.rstrip("/").split("/")[-1]
    ds = Dataset(path); t = load_truth(ds); rec = Reconstruction.load(f"/work/b35/rec/{name}.{VAR}.npz")
    e = sighting_errors(t, rec); names = list(ds.marks) + ["nose"] if len(ds.marks) < t["uv"].shape[2] else list(ds.marks)
    ev = e["virtual"]; er = e["real"]
    miss = ev["truly"] & er["truly"] & ~ev["ok"]
    wrong = ev["ok"] & ((ev["err"] > 3) | (er["err"] > 3))
    print(name)
    for i in range(miss.shape[1]):
        if miss[:, i].any() or wrong[:, i].any():
            s = "".join("W" if wrong[f, i] else ("." if miss[f, i] else ("-" if not (ev["truly"][f,i] and er["truly"][f,i]) else "o")) for f in range(miss.shape[0]))
            st = rec.status[:, :, i] if rec.status.ndim == 3 else None
            print(f"  {names[i]:20s} {s}")
