"""For each marker unmatched in both views after main's first-frame stage (ff.jsonl), the first frame it is
accepted within 3 px in both views, and how many frames it is, in main's saved reconstructions (reacq4/rec)."""
import json, os, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
ff = {}
for l in open('renders/examples/tracking/curv22/ff.jsonl'):
    r = json.loads(l)
    if not r['joint']: ff[r['set']] = set(r['unmatched'])
for s in ['default_1','default_2','default_4','default_105','default_108','default_111','default_112','default_114','hard_83','hard_85','hard_88','hard_90']:
    path = f'/work/reacq/sets/{s}' if os.path.isdir(f'/work/reacq/sets/{s}') else f'/work/deftrack/sets/{s}'
    ds = Dataset(path); names = list(ds.marks)
    e = sighting_errors(load_truth(ds), Reconstruction.load(f'/work/reacq4/rec/{s}.phys+r1.npz'))
    good = sum((e[v]['ok'] & (e[v]['err'] <= 3)) for v in e)   # (F, P): views right and accepted
    out = []
    for n in sorted(ff[s]):
        i = names.index(n); f = np.flatnonzero(good[:, i] == 2)
        out.append(f"{n}:{f[0] if len(f) else '-'}({int((good[:, i] == 2).sum())}/{len(good)})")
    print(s, 'unmatched at 0 -> first frame right in both views (frames right in both):', ' '.join(out))
