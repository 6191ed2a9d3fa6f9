"""Per-frame strip of one marker: A accepted within 3 px, X accepted over, a/x got not accepted, . lost, - not visible."""
import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
ds = Dataset(sys.argv[1]); names = list(ds.marks); t = load_truth(ds); m = sys.argv[2]; i = names.index(m)
for p in sys.argv[3:]:
    e = sighting_errors(t, Reconstruction.load(p))
    for v in e:
        x = e[v]; F = len(x['err'])
        s = ''.join('-' if not x['truly'][f, i] else '.' if not x['got'][f, i] else
                    ('A' if x['err'][f, i] <= 3 else 'X') if x['ok'][f, i] else ('a' if x['err'][f, i] <= 3 else 'x') for f in range(F))
        print(f"{p.split('/')[-1][:22]:22s} {v[:4]} {s}")
