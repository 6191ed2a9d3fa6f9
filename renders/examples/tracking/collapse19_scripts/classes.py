"""Frame 0, per view: each visible mark's class at the detector (truth for diagnosis only).
found: a detected dot within 1.5 px (floor 0.08); faint: a round response peak within 1.5 px under the floor;
elongated: a peak there, roundness < 0.3; unresolved: no response peak within 1.5 px at any floor.
Also the fitted Gaussian width (px) and depth of each mark's blob (median over plausible fits)."""
import json, sys
from pathlib import Path
import numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.recon.calibrate import RigCalibration
from lipgen.recon.dots import DotSettings, detect_dots, dot_peaks, ink_gray
from lipgen.recon.pipeline import dot_sigma_px, lab_frame
sys.path.insert(0, '/work/collapse19/diag')
from ff0 import fit_blob

rows = []
for name in sys.argv[1:]:
    ds = Dataset(Path('/work/data') / name)
    cal = RigCalibration.from_dict(json.loads((Path('/work/collapse19/calib') / f'{name}.json').read_text()))
    sigma = dot_sigma_px(cal, lab_frame(cal), float(ds.settings.dot_diameter))
    views = ds.rig.split_views(np.asarray(ds[0].image)); tr = ds.truth(0)
    for v, img in enumerate(views):
        gray = ink_gray(img)
        uv, _ = detect_dots(img, DotSettings(sigma=sigma))
        pk, ps, pr = dot_peaks(gray, DotSettings(sigma=sigma, min_contrast=0.005, noise_k=0.0))
        t = np.asarray(tr['uv'])[v]; vis = np.asarray(tr['visible'])[v]
        cls = {'found': 0, 'faint': 0, 'elongated': 0, 'unresolved': 0}
        faint_s, found_s, widths, depths = [], [], [], []
        for k in np.flatnonzero(vis):
            d = np.linalg.norm(uv - t[k], axis=1).min() if len(uv) else np.inf
            dp = np.linalg.norm(pk - t[k], axis=1); j = np.argmin(dp)
            if d < 1.5:
                c = 'found'; found_s.append(ps[j] if dp[j] < 1.5 else np.nan)
            elif dp[j] >= 1.5:
                c = 'unresolved'
            elif pr[j] < 0.3:
                c = 'elongated'
            else:
                c = 'faint'; faint_s.append(ps[j])
            cls[c] += 1
            _, _, s, a = fit_blob(gray, t[k], sigma)
            if 0.5 < s < 6 and 0 < a < 1:
                widths.append(s); depths.append(a)
        fs = np.array(faint_s)
        print(f"{name} {'mirror' if v == 0 else 'direct'}: vis {int(vis.sum())}  " + '  '.join(f'{k} {n}' for k, n in cls.items())
              + (f"  faint strength {fs.min():.3f}-{fs.max():.3f}" if len(fs) else '')
              + (f"  found strength med {np.nanmedian(found_s):.3f}" if len(found_s) else '')
              + f"  blob width med {np.median(widths):.2f} px (n {len(widths)}), depth med {np.median(depths):.3f}  [sigma {sigma:.2f}]", flush=True)
