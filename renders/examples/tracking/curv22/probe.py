"""Recall of candidate dot responses at the 'no peak' lost sightings (default dev sets) and at accepted ones,
and peaks per view image. usage: python probe.py"""
import sys, pickle, numpy as np, collections
sys.path.insert(0, '/work/main')
from scipy import ndimage
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.dots import DotSettings, ink_gray, dot_response, local_maxima, peak_roundness
rows = [x for x in pickle.load(open('/work/diagdef/lostrows.pkl', 'rb')) if x['dmin'] > 3 and x['dvf'] > 0]
by = collections.defaultdict(list)
for x in rows:
    by[(x['set'], x['f'])].append(x)
rng = np.random.default_rng(0)

def hess_eig(img, s):
    hxx = ndimage.gaussian_filter(img, s, order=(0, 2), mode='nearest')
    hyy = ndimage.gaussian_filter(img, s, order=(2, 0), mode='nearest')
    hxy = ndimage.gaussian_filter(img, s, order=(1, 1), mode='nearest')
    ht, dr = 0.5 * (hxx + hyy), np.sqrt(0.25 * (hxx - hyy) ** 2 + hxy ** 2)
    return s * s * (ht - dr), s * s * (ht + dr)      # small, large

def peaks_of(resp, st, floor):
    size = 2 * int(np.floor(st.separation / 2)) + 1
    pk = (resp == ndimage.maximum_filter(resp, size=size, mode='nearest')) & (resp > floor)
    e = int(np.ceil(2 * st.sigma)); pk[:e] = pk[-e:] = False; pk[:, :e] = pk[:, -e:] = False
    r, c = np.nonzero(pk)
    return np.column_stack([c, r]).astype(float), r, c

def responses(gray, st):
    s = st.sigma
    out = {}
    resp = dot_response(gray, st)
    pk = local_maxima(resp, st, st.min_contrast)
    r, c = np.nonzero(pk); rnd = peak_roundness(resp, r, c)[0]; k = rnd >= st.min_roundness
    out['tophat'] = (np.column_stack([c[k], r[k]]).astype(float), resp[r[k], c[k]])
    lap = s * s * ndimage.gaussian_laplace(gray, s, mode='nearest')
    pk = local_maxima(lap, st, -np.inf); r, c = np.nonzero(pk)
    k = peak_roundness(lap, r, c)[0] >= st.min_roundness
    out['log'] = (np.column_stack([c[k], r[k]]).astype(float), resp[r[k], c[k]])
    for name, sc in (('hmin', 1.0), ('hmin.7', 0.7)):
        small, large = hess_eig(gray, sc * s)
        R = np.maximum(small, 0)
        uv, r, c = peaks_of(R, st, 1e-4)
        out[name] = (uv, resp[r, c], R[r, c])
    return out

if __name__ == "__main__":
    stats = collections.defaultdict(collections.Counter)
    for n in sorted({x['set'] for x in rows}):
        d = pickle.load(open(f'/work/diagdef/data_default_{n}.pkl', 'rb'))
        st = DotSettings(sigma=d['sigma'])
        ds = Dataset(f'/work/deftrack/sets/default_{n}')
        tuv = load_truth(ds)['uv']
        frames = sorted({f for (s, f) in by if s == n})
        for f in frames:
            halves = ds.rig.split_views(ds[f].image)
            for v in range(2):
                xv = [x for x in by[(n, f)] if x['v'] == v]
                acc = np.flatnonzero(d['acc'][f] & np.all(np.isfinite(d['tuv'][f, v]), 1))
                if not xv and not len(acc): continue
                R = responses(ink_gray(halves[v]), st)
                for name, val in R.items():
                    uv = val[0]
                    stats[name]['images'] += 1; stats[name]['peaks'] += len(uv)
                    for x in xv:
                        t = tuv[f, v, x['p']]
                        dd = np.linalg.norm(uv - t, axis=1).min() if len(uv) else np.inf
                        stats[name]['nopeak_n'] += 1; stats[name]['nopeak_hit'] += int(dd <= 1.5)
                    for p in acc:
                        t = d['tuv'][f, v, p]
                        dd = np.linalg.norm(uv - t, axis=1).min() if len(uv) else np.inf
                        stats[name]['acc_n'] += 1; stats[name]['acc_hit'] += int(dd <= 1.5)
        print(n, {k: dict(v) for k, v in stats.items()}, flush=True)
