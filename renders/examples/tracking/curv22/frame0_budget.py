"""Main's losses on the 12 development sets split by the markers' state at frame 0 (ff.jsonl's main rows: wrong
or unmatched after the first-frame stage) against the others; main's saved reconstructions (reacq4/rec)."""
import json, os, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
ff = {}
for l in open('renders/examples/tracking/curv22/ff.jsonl'):
    r = json.loads(l)
    if not r['joint']: ff[r['set']] = set(r['wrong_names']) | set(r['unmatched'])
tot = np.zeros(4, int)
for s in ['default_1','default_2','default_4','default_105','default_108','default_111','default_112','default_114','hard_83','hard_85','hard_88','hard_90']:
    path = f'/work/reacq/sets/{s}' if os.path.isdir(f'/work/reacq/sets/{s}') else f'/work/deftrack/sets/{s}'
    ds = Dataset(path); names = list(ds.marks)
    e = sighting_errors(load_truth(ds), Reconstruction.load(f'/work/reacq4/rec/{s}.phys+r1.npz'))
    bad0 = np.array([n in ff[s] for n in names])
    miss = sum((e[v]['truly'] & ~e[v]['ok']).sum(0) for v in e)
    over = sum((e[v]['ok'] & (e[v]['err'] > 3)).sum(0) for v in e)
    row = np.array([miss[bad0].sum(), miss[~bad0].sum(), over[bad0].sum(), over[~bad0].sum()])
    tot += row
    print(f"{s:12s} frame-0 bad markers {int(bad0.sum()):2d}: missing {row[0]:4d} (them) / {row[1]:4d} (others); "
          f"over 3 px {row[2]:3d} / {row[3]:3d}")
print('total', tot.tolist())
