import sys, pickle, numpy as np
sys.path.insert(0, "/work/wt/w39")
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.backfill import neighbour_motion
from lipgen.recon.gapfill import view_peaks
from lipgen.recon.pointreg import layout_spacing
name, f, ms = sys.argv[1], int(sys.argv[2]), [int(x) for x in sys.argv[3].split(",")]
g = pickle.load(open(f"/work/b39/grab_{name}.pkl", "rb"))
ds = Dataset(f"/work/sets/{name}"); t = load_truth(ds)
tr = g["tracks"]; acc = g["accepted"]; sure = g["sure"]
for m in ms:
    print("marker", m, "acc f-1,f:", acc[f-1, m], acc[f, m], "sure f-1:", sure[f-1, m])
imgs = ds.rig.split_views(np.asarray(ds[f].image))
both = acc[f-1] & acc[f]
for v in range(2):
    peaks, gray = view_peaks(imgs[v], g["dots"], g["floor"])
    for m in ms:
        mv = neighbour_motion(g["reference"][v], tr[v].uv[f-1], tr[v].uv[f], both, m, layout_spacing(g["reference"][v]))
        pred = tr[v].uv[f-1, m] + mv
        d = np.linalg.norm(peaks - pred, axis=1); j = np.argsort(d)[:3]
        print(v, m, "pred err vs truth", np.linalg.norm(pred - t["uv"][f, v, m]).round(2), "near peaks", d[j].round(2),
              "truth-to-peaks", np.linalg.norm(peaks[j] - t["uv"][f, v, m], axis=1).round(2))
from lipgen.recon.dots import refine_centroids
from lipgen.rig.pinhole import triangulate
cams = g["cameras"]
got = []
for v in range(2):
    peaks, gray = view_peaks(imgs[v], g["dots"], g["floor"])
    row = []
    for m in ms:
        d = np.linalg.norm(peaks - t["uv"][f, v, m], axis=1); j = int(np.argmin(d))
        r = refine_centroids(gray, peaks[j][None], g["dots"].sigma, window=g["dots"].window)[0]
        row.append(r); print("view", v, "m", m, "refined err", np.linalg.norm(r - t["uv"][f, v, m]).round(2))
    got.append(row)
for k, m in enumerate(ms):
    print("m", m, "gap", triangulate(cams[1], got[1][k][None], cams[0], got[0][k][None])[1][0], "limit", g["max_gap"])
