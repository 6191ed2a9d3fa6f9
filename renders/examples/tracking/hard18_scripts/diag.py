"""Diagnosis: what the detector sees at the true projections of mirror sightings main lost.

usage: PYTHONPATH=/work/hard18/base python diag.py SET [SET...]   (needs /work/hard18/out/main/SET.npz)
Every frame; per view, for visible sightings: accepted / tracked-not-accepted / lost; at the truth:
smoothed top-hat response peak (nearest local max within 2 px), relative darkness (top-hat / closing,
smoothed) at that peak, roundness, the ROI noise threshold, and whether the tracker's detector
(floor as the tracker would set it) has a round dot within 1.5 px.
"""
import json, sys
from pathlib import Path
import numpy as np
from scipy import ndimage
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.calibrate import RigCalibration
from lipgen.recon.dots import DotSettings, ink_gray, dot_peaks
from lipgen.recon.pipeline import dot_sigma_px, lab_frame

ROOT = Path("/work/hard18")


def maps(gray, sigma, smoothing=0.6):
    radius = int(np.ceil(3.0 * sigma)) + 1
    closed = ndimage.grey_closing(gray, size=(2 * radius + 1,) * 2, mode="nearest")
    dark = closed - gray
    resp = ndimage.gaussian_filter(dark, smoothing * sigma, mode="nearest")
    rel = ndimage.gaussian_filter(dark / np.maximum(closed, 1e-3), smoothing * sigma, mode="nearest")
    return resp, rel, closed


def near_peak(resp, uv, r=2):
    c, rr = int(round(uv[0])), int(round(uv[1]))
    h, w = resp.shape
    a0, a1, b0, b1 = max(rr - r, 1), min(rr + r + 1, h - 1), max(c - r, 1), min(c + r + 1, w - 1)
    win = resp[a0:a1, b0:b1]
    i = np.unravel_index(np.argmax(win), win.shape)
    y, x = a0 + i[0], b0 + i[1]
    loc = resp[y - 1:y + 2, x - 1:x + 2]
    is_max = resp[y, x] >= loc.max()
    ryy = resp[y + 1, x] + resp[y - 1, x] - 2 * resp[y, x]
    rxx = resp[y, x + 1] + resp[y, x - 1] - 2 * resp[y, x]
    rxy = 0.25 * (resp[y + 1, x + 1] + resp[y - 1, x - 1] - resp[y + 1, x - 1] - resp[y - 1, x + 1])
    ht, dr = 0.5 * (rxx + ryy), np.sqrt(0.25 * (rxx - ryy) ** 2 + rxy ** 2)
    weak, strong = ht + dr, ht - dr
    rnd = float(np.clip(weak / strong, 0, 1)) if strong < 0 else 0.0
    return y, x, bool(is_max), rnd


def run(name):
    ds = Dataset(Path("/work/data") / name)
    cal = RigCalibration.from_dict(json.loads((ROOT / "calib" / f"{name}.json").read_text()))
    sigma = dot_sigma_px(cal, lab_frame(cal), float(ds.settings.dot_diameter))
    z = np.load(ROOT / "out" / "main" / f"{name}.npz")
    truth = load_truth(ds)
    F, P = z["accepted"].shape[0], z["accepted"].shape[1] - 1
    rows = []
    global lure_rows
    lure_rows = []
    for f in range(F):
        views = ds.rig.split_views(ds[f].image)
        for v in range(2):
            gray = ink_gray(views[v])
            resp, rel, closed = maps(gray, sigma)
            vis = truth["visible"][f, v, :P]
            tuv = truth["uv"][f, v, :P]
            acc = z["accepted"][f, :P]
            st = z["status"][v, f, :P]
            # ROI like the tracker: box round the markers + 60 px
            ok = vis & np.isfinite(tuv).all(1)
            lo = np.maximum(np.floor(tuv[ok].min(0) - 60).astype(int), 0)
            hi = np.minimum(np.ceil(tuv[ok].max(0) + 60).astype(int), gray.shape[::-1])
            sub = resp[lo[1]:hi[1], lo[0]:hi[0]]
            med = np.median(sub); mad = 1.4826 * np.median(np.abs(sub - med))
            noise = med + 4.5 * mad
            subr = rel[lo[1]:hi[1], lo[0]:hi[0]]
            medr = np.median(subr); madr = 1.4826 * np.median(np.abs(subr - medr))
            noiser = medr + 4.5 * madr
            got = st != 3  # LOST = 3
            typ = np.median([resp[int(round(t[1])), int(round(t[0]))] for t in tuv[ok & acc]]) if (ok & acc).any() else np.nan
            floor = 0.08 if not (0 < 0.7 * typ < 0.08) else max(0.7 * typ, 0.05)
            g = gray[lo[1]:hi[1], lo[0]:hi[0]]
            pk, pstr, prnd = dot_peaks(g, DotSettings(sigma=sigma, min_contrast=floor))
            pk = pk + lo
            pk0, pstr0, prnd0 = dot_peaks(g, DotSettings(sigma=sigma, min_contrast=0.01, noise_k=0.0))
            pk0 = pk0 + lo
            # lures: low-floor round peaks > 3 px from every true marker of this view (any visibility)
            allt = truth["uv"][f, v][np.isfinite(truth["uv"][f, v]).all(1)]
            far = np.linalg.norm(pk0[:, None] - allt[None], axis=2).min(1) > 3 if len(pk0) else np.zeros(0, bool)
            rr = prnd0 >= 0.3
            ia = pk0.astype(int)
            lure_rows.append(dict(set=name, f=f, v=v, abs=pstr0[far & rr].tolist(),
                                  rel=rel[ia[far & rr, 1], ia[far & rr, 0]].tolist(),
                                  bg=closed[ia[far & rr, 1], ia[far & rr, 0]].tolist()))
            for p in np.flatnonzero(ok):
                others = np.delete(tuv, p, 0)[np.delete(ok, p)]
                dn = np.linalg.norm(others - tuv[p], axis=1).min() if len(others) else np.inf
                d = np.linalg.norm(pk - tuv[p], axis=1) if len(pk) else np.array([np.inf])
                j = int(np.argmin(d))
                d0 = np.linalg.norm(pk0 - tuv[p], axis=1) if len(pk0) else np.array([np.inf])
                j0 = int(np.argmin(d0))
                extra = dict(floor=float(floor), nn=float(dn), dpk=float(d[j]),
                             pk_rnd=float(prnd[j]) if len(pk) else 0.0, pk_str=float(pstr[j]) if len(pk) else 0.0,
                             dpk0=float(d0[j0]), pk0_rnd=float(prnd0[j0]) if len(pk0) else 0.0,
                             pk0_str=float(pstr0[j0]) if len(pk0) else 0.0)
                y, x, ismax, rnd = near_peak(resp, tuv[p])
                rows.append(dict(set=name, f=f, v=v, p=int(p), acc=bool(acc[p]), status=int(st[p]),
                                 abs=float(resp[y, x]), rel=float(rel[y, x]), bg=float(closed[y, x]),
                                 ismax=ismax, rnd=rnd, noise=float(noise), noiser=float(noiser),
                                 err=float(np.linalg.norm(z["uv"][v, f, p] - tuv[p])), **extra))
    return rows


if __name__ == "__main__":
    for s in sys.argv[1:]:
        rows = run(s)
        (ROOT / "diag" / f"{s}.json").write_text(json.dumps(rows))
        (ROOT / "diag" / f"{s}_lures.json").write_text(json.dumps(lure_rows))
        print(s, len(rows), flush=True)
