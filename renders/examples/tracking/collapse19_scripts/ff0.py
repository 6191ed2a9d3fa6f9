"""Frame 0 of a set: per mark, per view, what the blob looks like and what the detector returns.
usage: PYTHONPATH=tree python ff0.py SET [SET...]   (truth read for diagnosis only)"""
import json, sys
from pathlib import Path
import numpy as np
from scipy import ndimage
from lipgen.dataset.layout import Dataset
from lipgen.recon.calibrate import RigCalibration
from lipgen.recon.dots import DotSettings, ink_gray, darkness, detect_dots, dot_peaks, _lm_fit
from lipgen.recon.pipeline import dot_sigma_px, lab_frame
from lipgen.rig.camera import VIEWS

def cal_for(name):
    for p in (Path('/work/collapse19/calib')/f'{name}.json', Path('/work/hard17/calib')/f'{name}.json'):
        if p.exists():
            return RigCalibration.from_dict(json.loads(p.read_text())), str(p)
    return None, None

def fit_blob(gray, uv, sigma):
    """Gaussian dot on quadratic bg fit at uv (no window): (du, dv, s, a)."""
    half = int(np.ceil(3.0 * 2.5 * sigma)) + 1
    offs = np.arange(-half, half + 1, dtype=float)
    base = np.round(uv)
    h, w = gray.shape
    cols = np.clip(base[0] + offs, 0, w - 1).astype(int); rows = np.clip(base[1] + offs, 0, h - 1).astype(int)
    img = gray[rows[:, None], cols[None, :]].reshape(1, -1)
    dy, dx = (a.ravel() for a in np.meshgrid(offs, offs, indexing='ij'))
    bg = np.stack([np.ones_like(dx), dx, dy, dx*dx, dx*dy, dy*dy], 1)
    u, v = uv[0]-base[0], uv[1]-base[1]
    g = np.exp(-((dx-u)**2+(dy-v)**2)/(2*sigma**2))
    design = np.concatenate([bg, -g[:, None]], 1)
    lin = np.linalg.lstsq(design, img[0], rcond=None)[0]
    p = np.array([[u, v, sigma, lin[6], *lin[:6]]])
    wt = np.exp(-((dx-u)**2+(dy-v)**2)/(2*(2.5*sigma)**2))[None]
    p = _lm_fit(img, bg, dx, dy, p, 30, 2.5*sigma, wt)
    return p[0, 0], p[0, 1], p[0, 2], p[0, 3]

def log_scale(gray, uv, scales):
    """scale-normalised -LoG at the pixel nearest uv (max within 1 px) per scale."""
    r, c = int(round(uv[1])), int(round(uv[0]))
    out = []
    for s in scales:
        L = -s*s*ndimage.gaussian_laplace(-gray, s)  # dark blob -> positive
        L = -L
        out.append(L[r-1:r+2, c-1:c+2].max())
    return np.array(out)

def main(name):
    ds = Dataset(Path('/work/data')/name)
    cal, src = cal_for(name)
    T = lab_frame(cal)
    sigma = dot_sigma_px(cal, T, float(ds.settings.dot_diameter))
    st = DotSettings(sigma=sigma)
    raw = ds[0].image
    views = ds.rig.split_views(np.asarray(raw))
    tr = ds.truth(0)
    marks = list(ds.manifest['marks'])
    scales = np.array([1.0, 1.3, 1.6, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0])
    print(f'== {name} sigma {sigma:.2f} (cal {src})')
    for v, img in enumerate(views):
        gray = ink_gray(img)
        uvd, sd = detect_dots(img, st)
        dark = darkness(gray, sigma)
        resp = ndimage.gaussian_filter(dark, st.smoothing*sigma, mode='nearest')
        med = np.median(resp); mad = 1.4826*np.median(np.abs(resp-med))
        thr = max(st.min_contrast, med+st.noise_k*mad)
        pk, ps, pr = dot_peaks(gray, DotSettings(sigma=sigma, min_contrast=0.005, noise_k=0.0))
        truv = np.asarray(tr['uv'])[v]; vis = np.asarray(tr['visible'])[v]
        print(f'-- {VIEWS[v]}: {len(uvd)} dots found; threshold {thr:.3f} (med {med:.3f} mad {mad:.3f})')
        print('   mark                vis  nn_dot  resp@t  pk<1.5(str,rnd)   fit s   fit a  LoGbest  nbr_mark')
        nfound = 0
        for k, m in enumerate(marks):
            t = truv[k]
            if not np.all(np.isfinite(t)):
                print(f'   {m:20s} {int(vis[k])}  no uv'); continue
            dd = np.linalg.norm(uvd - t, axis=1).min() if len(uvd) else np.inf
            nfound += bool(vis[k] and dd < 1.5)
            r, c = int(round(t[1])), int(round(t[0]))
            rt = resp[r, c]
            dp = np.linalg.norm(pk - t, axis=1)
            j = np.argmin(dp)
            pkstr = f'{dp[j]:.1f}px {ps[j]:.3f} {pr[j]:.2f}' if dp[j] < 1.5 else f'none ({dp[j]:.1f})'
            du, dv, s, a = fit_blob(gray, t, sigma)
            L = log_scale(gray, t, scales)
            others = np.delete(truv, k, 0)
            nb = np.nanmin(np.linalg.norm(others - t, axis=1))
            print(f'   {m:20s} {int(vis[k])}  {dd:6.1f}  {rt:6.3f}  {pkstr:17s} {s:6.2f} {a:6.3f}  {scales[np.argmax(L)]:4.1f}   {nb:5.1f}')
        print(f'   visible marks with a dot within 1.5 px: {nfound} / {int(vis.sum())}')

if __name__ == '__main__':
    for n in sys.argv[1:]:
        main(n)
