import pickle, numpy as np, matplotlib, random
matplotlib.use("Agg"); import matplotlib.pyplot as plt
from lipgen.dataset.layout import Dataset
rows = pickle.load(open("/work/diagdef/lostrows.pkl", "rb"))
none = [r for r in rows if r["dmin"] > 3]
random.seed(0); sel = random.sample(none, 10)
fig, axs = plt.subplots(2, 5, figsize=(16, 7))
for ax, r in zip(axs.flat, sel):
    n = r["set"]; d = pickle.load(open(f"/work/diagdef/data_default_{n}.pkl", "rb"))
    ds = Dataset(f"/work/deftrack/sets/default_{n}")
    img = ds.rig.split_views(ds[r["f"]].image)[r["v"]]
    t = d["tuv"][r["f"], r["v"]]; c0, r0 = np.round(t[r["p"]]).astype(int); h = 18
    ax.imshow(img, extent=(-0.5, img.shape[1]-0.5, img.shape[0]-0.5, -0.5)); ax.set_xlim(c0-h, c0+h); ax.set_ylim(r0+h, r0-h)
    vis = d["vis"][r["f"], r["v"]]; ax.plot(t[vis, 0], t[vis, 1], "c+", ms=8)
    ax.plot(*t[r["p"]], "r+", ms=14, mew=2)
    ax.set_title(f"d{n} f{r['f']} {'mirror' if r['v']==0 else 'direct'} {d['names'][r['p']]}\nresp {r['resp']:.2f} dvf {r['dvf']:.2f}", fontsize=8)
plt.tight_layout(); plt.savefig("/work/diagdef/nopeak_samples.png", dpi=80)
