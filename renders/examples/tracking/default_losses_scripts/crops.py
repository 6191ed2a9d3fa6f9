import pickle, numpy as np, matplotlib
matplotlib.use("Agg"); import matplotlib.pyplot as plt
from lipgen.dataset.layout import Dataset
from lipgen.recon.dots import DotSettings, ink_gray, dot_peaks
rows = pickle.load(open("/work/diagdef/lostrows.pkl", "rb"))
VN = ("mirror", "direct")
def pick(setn, name, cls):
    d = pickle.load(open(f"/work/diagdef/data_default_{setn}.pkl", "rb"))
    p = d["names"].index(name)
    c = [r for r in rows if r["set"] == setn and r["p"] == p and (r["dmin"] <= 1.5 if cls == "present" else r["dmin"] > 3)]
    return d, c[len(c)//2] if c else None
cases = [(2, "corner_left", "present"), (102, "lower_corner_left", "none"), (4, "lower_corner_right", "present"), (104, "bow_dip", "none")]
fig, axs = plt.subplots(1, 4, figsize=(16, 4.4))
for ax, (n, name, cls) in zip(axs, cases):
    d, r = pick(n, name, cls)
    if r is None: ax.set_title(f"default_{n} {name}: none"); continue
    ds = Dataset(f"/work/deftrack/sets/default_{n}")
    img = ds.rig.split_views(ds[r["f"]].image)[r["v"]]
    pk, s, rnd = dot_peaks(ink_gray(img), DotSettings(sigma=d["sigma"]))
    t = d["tuv"][r["f"], r["v"]]; c0, r0 = np.round(t[r["p"]]).astype(int); h = 22
    ax.imshow(img, extent=(-0.5, img.shape[1]-0.5, img.shape[0]-0.5, -0.5))
    ax.set_xlim(c0-h, c0+h); ax.set_ylim(r0+h, r0-h)
    vis = d["vis"][r["f"], r["v"]]
    ax.plot(t[vis, 0], t[vis, 1], "c+", ms=10, mew=1.2, label="true marks")
    ax.plot(*t[r["p"]], "r+", ms=16, mew=2.5, label="lost mark (truth)")
    ok = rnd >= 0.3
    ax.plot(pk[ok, 0], pk[ok, 1], "o", mfc="none", mec="lime", ms=9, label="round peak")
    ax.plot(pk[~ok, 0], pk[~ok, 1], "s", mfc="none", mec="yellow", ms=8, label="elongated peak")
    tu = d["uv"][r["v"], r["f"]]; ax.plot(tu[:, 0], tu[:, 1], "bx", ms=8, label="tracked")
    ax.set_title(f"default_{n} f{r['f']} {VN[r['v']]}\n{name} lost ({'dot detected' if cls=='present' else 'no peak'})", fontsize=9)
axs[0].legend(fontsize=7, loc="lower left")
plt.tight_layout(); plt.savefig("/work/diagdef/lost_crops.png", dpi=90)
print("ok")
