"""Diagnosis of tracking losses on the default preset (read-only on /work/main)."""
import json, sys, pickle
import numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
from lipgen.recon.dots import DotSettings, ink_gray, dot_peaks, dot_response, peak_roundness
from scipy import ndimage

SETS = [int(a) for a in sys.argv[1:]] or [1, 2, 3, 4, 5, 100, 101, 102, 103, 104]
VIEWS = ("virtual", "real")
out = {}
for n in SETS:
    name = f"default_{n}"
    ds = Dataset(f"/work/deftrack/sets/{name}")
    tr = load_truth(ds)
    r = Reconstruction.load(f"/work/deftrack/work/{name}.recon.npz")
    e = sighting_errors(tr, r)
    names = list(r.info["marker_names"]) + ["nose"]
    F, P1 = r.status.shape[1:]
    dd = float(ds.settings.dot_diameter)
    # approximate the pipeline's sigma: 0.85 r px_per_mm in the view that sees dots smallest
    truths = [ds.truth(i) for i in range(F)]
    depth = np.stack([t["depth"] for t in truths])  # (F,2,k)
    K = ds.rig.camera.K[0][0] if hasattr(ds.rig.camera, "K") else 581.8
    K = float(np.asarray(ds.rig.camera.K)[0, 0])
    ppm = K / np.nanmedian(depth[:, :, :-1], axis=(0, 2)).max()
    sigma = float(np.clip(0.85 * dd / 2 * ppm, 1.2, 6.0))
    st = DotSettings(sigma=sigma)
    dvf = np.stack([t["dot_visible_fraction"] for t in truths])  # (F,2,k)
    facing = np.stack([t["facing"] for t in truths]); occl = np.stack([t["occluded"] for t in truths])
    rec = dict(names=names, sigma=sigma, F=F, P1=P1, status=r.status, uv=r.uv, tuv=tr["uv"], vis=tr["visible"],
               err=np.stack([e[v]["err"] for v in VIEWS]), got=np.stack([e[v]["got"] for v in VIEWS]),
               acc=e["real"]["accepted"], dvf=dvf, pose=tr["pose"], marks_model=tr["marks_model"],
               manifest_subject=ds.manifest["subject"]["shape"], head=ds.manifest["scene"]["head"],
               dot_diameter=dd)
    # per lost sighting: detector evidence near the true projection
    lost = [(tr["visible"][:, i] & ~e[v]["got"]) for i, v in enumerate(VIEWS)]  # (F,P1) each
    rows = []
    for f in range(F):
        need = [np.flatnonzero(lost[v][f]) for v in range(2)]
        img = ds[f].image
        halves = ds.rig.split_views(img)
        for v in range(2):
            gray = ink_gray(halves[v])
            resp = dot_response(gray, st)
            pk, strength, rnd = dot_peaks(gray, st, response=resp)
            med = np.median(resp); mad = 1.4826 * np.median(np.abs(resp - med))
            thr = max(st.min_contrast, med + st.noise_k * mad)
            # truth positions of all marks this frame/view
            T = tr["uv"][f, v]
            # strength of every visible dot (for the per-set dot-darkness stats)
            if f % 5 == 0:
                for p in np.flatnonzero(tr["visible"][f, v]):
                    c, rr = np.round(T[p]).astype(int)
                    if 2 <= rr < gray.shape[0]-2 and 2 <= c < gray.shape[1]-2:
                        rows.append(dict(kind="all", f=f, v=v, p=p, resp=float(resp[rr-1:rr+2, c-1:c+2].max()), thr=thr))
            for p in need[v]:
                t = T[p]
                d = np.linalg.norm(pk - t, axis=1) if len(pk) else np.array([np.inf])
                j = int(np.argmin(d)) if len(pk) else -1
                c, rr = np.round(t).astype(int)
                ok_in = 2 <= rr < gray.shape[0]-2 and 2 <= c < gray.shape[1]-2
                # best local response and its roundness within 1.5 px
                lr = float(resp[rr-1:rr+2, c-1:c+2].max()) if ok_in else np.nan
                others = np.linalg.norm(np.delete(T, p, 0) - t, axis=1)
                onames = [nm for i, nm in enumerate(names) if i != p]
                # peak at the truth: is that peak nearer another marker's truth?
                nearest_other = onames[int(np.nanargmin(others))]
                # where is the tracked position of other markers (is the peak taken by another marker)?
                taken = False
                if j >= 0 and d[j] <= 1.5:
                    tu = np.delete(r.uv[v, f], p, 0)
                    taken = bool(np.nanmin(np.linalg.norm(tu - pk[j], axis=1), initial=np.inf) <= 1.5)
                rows.append(dict(kind="lost", f=f, v=v, p=p, dmin=float(d[j]) if j >= 0 else np.inf,
                                 rnd=float(rnd[j]) if j >= 0 else np.nan, strength=float(strength[j]) if j >= 0 else np.nan,
                                 resp=lr, thr=thr, dvf=float(dvf[f, v, p]), other_d=float(np.nanmin(others)),
                                 other=nearest_other, taken=taken, status_prev=int(r.status[v, f-1, p]) if f else -1))
    rec["rows"] = rows
    out[name] = rec
    print(name, "sigma", round(sigma, 3), "lost", sum(1 for x in rows if x["kind"] == "lost"), flush=True)
    with open(f"/work/diagdef/data_{name}.pkl", "wb") as fh:
        pickle.dump(rec, fh)
