"""R (scale-normalised smaller Hessian eigenvalue, sigma*0.7) at the nearest peak to the truth: no-peak lost vs
accepted sightings; and count of peaks per image above fractions of the view's median accepted R."""
import sys, pickle, numpy as np, collections
sys.path.insert(0, '/work/main')
from scipy import ndimage
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.dots import DotSettings, ink_gray
sys.path.insert(0, "renders/examples/tracking/curv22")
from probe import hess_eig, peaks_of, by
res = collections.defaultdict(list)
for n in [1, 2, 100, 103]:
    d = pickle.load(open(f'/work/diagdef/data_default_{n}.pkl', 'rb'))
    st = DotSettings(sigma=d['sigma'])
    ds = Dataset(f'/work/deftrack/sets/default_{n}')
    tuv = load_truth(ds)['uv']
    for f in sorted({f for (s, f) in by if s == n}):
        halves = ds.rig.split_views(ds[f].image)
        for v in range(2):
            xv = [x for x in by[(n, f)] if x['v'] == v]
            acc = np.flatnonzero(d['acc'][f] & np.all(np.isfinite(d['tuv'][f, v]), 1))
            if not xv or not len(acc): continue
            small, large = hess_eig(ink_gray(halves[v]), 0.7 * st.sigma)
            R = np.maximum(small, 0); rnd = np.where(large > 0, small / np.maximum(large, 1e-12), 0)
            uv, r, c = peaks_of(R, st, 1e-4)
            def near(t):
                dd = np.linalg.norm(uv - t, axis=1); i = dd.argmin(); return dd[i], R[r[i], c[i]], rnd[r[i], c[i]]
            ra = [near(d['tuv'][f, v, p]) for p in acc]
            med = np.median([x[1] for x in ra if x[0] <= 1.5])
            for x in xv:
                dd, rv, rn = near(tuv[f, v, x['p']])
                if dd <= 1.5: res['nopeak_rel'].append(rv / med); res['nopeak_rnd'].append(rn)
            for dd, rv, rn in ra:
                if dd <= 1.5: res['acc_rel'].append(rv / med); res['acc_rnd'].append(rn)
            allrel = R[r, c] / med
            for fr in (0.1, 0.2, 0.3, 0.5):
                res[f'peaks>{fr}'].append((allrel > fr).sum())
for k, v in res.items():
    v = np.array(v); print(k, len(v), np.percentile(v, [5, 10, 25, 50, 75, 90]).round(3))
