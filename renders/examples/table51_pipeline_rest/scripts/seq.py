import sys, json, numpy as np
sys.path.insert(0, '/work/main')
from pathlib import Path
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
W = Path('/work/t51p80/work')
seed = int(sys.argv[1]); q = json.loads(sys.argv[2])
ds = Dataset(W / f"s{seed}_train")
man = json.loads((W / f"s{seed}_train/manifest.json").read_text())
print({k: man[k] for k in man if k in ("motion", "script", "visemes")} if False else list(man.keys()))
tr = load_truth(ds); P = 16
marks = tr["marks_model"][:, :P]; trest = ds.rest_marks()[:P]
d = np.sqrt(np.mean(np.sum((marks - trest)**2, -1), 1))
sp = np.r_[np.nan, np.sqrt(np.mean(np.sum((marks[2:] - marks[:-2])**2, -1), 1)) / 2, np.nan]
for f in range(len(d)):
    print(f, "%.2f %.2f" % (d[f], sp[f]), "*" if f in q else "")
