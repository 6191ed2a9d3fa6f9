import pickle, sys, numpy as np, collections
tot = collections.Counter()
for s in sys.argv[1:]:
    d = pickle.load(open(f'/work/diagdef/data_default_{s}.pkl', 'rb'))
    m = np.load(f'/work/vis/d{s}.npy')
    n = {(int(a), int(b), int(c)): int(e) for a, b, c, _, _, e in m}
    rows = [r for r in d['rows'] if r['kind'] == 'lost' and r['dmin'] > 3]
    px = np.array([n[(r['f'], r['v'], r['p'])] for r in rows])
    allvis = np.array([e for a, b, c, vis, _, e in m if vis])
    c = collections.Counter(np.digitize(px, [1, 4, 8]))
    print(s, 'nopeak', len(rows), 'label px 0/1-3/4-7/8+:', [c[i] for i in range(4)],
          'all visible: median px', np.median(allvis), ' share <=3 px', round(float((allvis <= 3).mean()), 4))
    for i in range(4): tot[i] += c[i]
print('pooled', [tot[i] for i in range(4)])
