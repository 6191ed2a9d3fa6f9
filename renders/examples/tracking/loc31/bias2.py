import sys, json, numpy as np
from lipgen.evaluate.scoring import load_truth, accepted_sightings
from lipgen.recon.pipeline import Reconstruction
from lipgen.dataset.layout import Dataset
names = None
tab = {}
for name in sys.argv[1:]:
    m = json.load(open(f"/work/sets/{name}/manifest.json"))
    marks = m["marks"]; names = [mk["name"] if isinstance(mk, dict) else mk for mk in (marks if isinstance(marks, list) else marks.get("names", []))]
    truth = load_truth(Dataset(f"/work/sets/{name}"))
    rec = Reconstruction.load(f"/work/speed30/rc/main/{name}.npz")
    acc = accepted_sightings(rec)
    for v in (0, 1):
        d = rec.uv[v] - truth["uv"][:, v]
        ok = np.asarray(truth["visible"][:, v], bool) & acc & (np.linalg.norm(d, axis=-1) <= 3)
        for p in range(d.shape[1]):
            if ok[:, p].sum() > 5:
                b = d[ok[:, p], p].mean(0); sd = d[ok[:, p], p].std(0)
                tab.setdefault(p, []).append(f"{'VR'[v]}{name[4:]}:({b[0]:+.2f},{b[1]:+.2f})±{np.hypot(*sd):.2f}")
print(type(marks), str(marks)[:300])
for p, row in tab.items():
    print(p, names[p] if names and p < len(names) else "", " ".join(row))
