"""Dev measurement (spent sets, truth read): for each accepted sighting, is there an alternative 3-D point near
it -- a direct-view peak no marker holds within R px, with a mirror peak or blob no marker holds within R px of
the marker's mirror sighting, their rays meeting within the sequence's accepted ray gaps (95th pct)?
Rates for right (< 1.5 px both views) and wrong (> 3 px both views) sightings."""
import sys, os, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from spent import spent
from lipgen.recon.dots import as_gray, dot_peaks
from lipgen.recon.blobs import blob_peaks
from lipgen.rig.pinhole import triangulate
root, var, R = sys.argv[1], sys.argv[2], float(sys.argv[3])
tot = {"right": [0, 0], "wrong": [0, 0]}
for name in sys.argv[4:]:
    d = spent(root, name, var)
    if d is None:
        continue
    ds, rec, acc, err, cal, T, st = (d[k] for k in ("ds", "rec", "acc", "err", "cal", "T", "dots"))
    cams = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3]).views
    lim = np.nanpercentile(rec.ray_gap[acc], 95)
    cnt = {"right": [0, 0], "wrong": [0, 0]}
    for f in range(acc.shape[0]):
        views = ds.rig.split_views(np.asarray(ds[f].image))
        free = []
        for v in range(2):
            g = as_gray(views[v]); uv, _, _ = dot_peaks(g, st)
            if v == 0:
                b, _ = blob_peaks(g, st, exclude=uv); uv = np.vstack([uv, b]) if len(b) else uv
            held = rec.uv[v, f][acc[f]]
            free.append(uv[np.linalg.norm(uv[:, None] - held[None], axis=-1).min(axis=1) > 2.0])
        for k in np.flatnonzero(acc[f, :-1]):
            if (err[:, f, k] < 1.5).all(): c = "right"
            elif (err[:, f, k] > 3).all(): c = "wrong"
            else: continue
            p = free[1][np.linalg.norm(free[1] - rec.uv[1, f, k], axis=1) <= R]
            q = free[0][np.linalg.norm(free[0] - rec.uv[0, f, k], axis=1) <= R]
            hit = False
            if len(p) and len(q):
                P = np.repeat(p, len(q), 0); Q = np.tile(q, (len(p), 1))
                _, gap = triangulate(cams[1], P, cams[0], Q)
                hit = bool((gap <= lim).any())
            cnt[c][0] += hit; cnt[c][1] += 1
    for c in cnt: tot[c][0] += cnt[c][0]; tot[c][1] += cnt[c][1]
    print(f"{name} gap95 {lim:.2f} right {cnt['right'][0]}/{cnt['right'][1]} wrong {cnt['wrong'][0]}/{cnt['wrong'][1]}", flush=True)
print("total", {c: f"{a}/{b} ({100*a/max(b,1):.1f}%)" for c, (a, b) in tot.items()})
