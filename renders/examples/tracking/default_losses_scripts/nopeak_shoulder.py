"""The 'no peak' lost sightings of the default development sets: is the dot's top-hat response a 3x3 local
maximum (suppressed by the separation window) or a shoulder with no local maximum at all?"""
import sys, pickle, numpy as np, collections
sys.path.insert(0, '/work/main')
from scipy import ndimage
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.dots import DotSettings, ink_gray, dot_response
rows = [x for x in pickle.load(open('/work/diagdef/lostrows.pkl', 'rb')) if x['dmin'] > 3 and x['dvf'] > 0]
by = collections.defaultdict(list)
for x in rows:
    by[(x['set'], x['f'])].append(x)
sets = sorted({x['set'] for x in rows})
out = collections.Counter()
for n in sets:
    sig = pickle.load(open(f'/work/diagdef/data_default_{n}.pkl', 'rb'))['sigma']
    st = DotSettings(sigma=sig)
    ds = Dataset(f'/work/deftrack/sets/default_{n}')
    tuv = load_truth(ds)['uv']
    sep = st.separation if hasattr(st, 'separation') else None
    for (s, f), xs in sorted(by.items()):
        if s != n: continue
        halves = ds.rig.split_views(ds[f].image)
        for v in range(2):
            xv = [x for x in xs if x['v'] == v]
            if not xv: continue
            resp = dot_response(ink_gray(halves[v]), st)
            loc3 = resp == ndimage.maximum_filter(resp, size=3, mode='nearest')
            for x in xv:
                c, r = np.round(tuv[f, v, x['p']]).astype(int)
                win = loc3[r-2:r+3, c-2:c+3]
                out['local max (3x3) within 2 px' if win.any() else 'shoulder: no local max within 2 px'] += 1
    print(n, dict(out), 'separation', sep, flush=True)
