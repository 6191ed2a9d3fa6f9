import sys, json
sys.path.insert(0, '/work/collapse19/diag')
import numpy as np
from dataclasses import replace
from pathlib import Path
import ffstage as f
from lipgen.dataset.layout import Dataset
from lipgen.recon.dots import DotSettings, detect_dots
from lipgen.recon.stereo_init import repose_layout, stereo_candidates
from lipgen.recon.pipeline import dot_sigma_px, lab_frame
for name in sys.argv[1:]:
    ds = Dataset(Path('/work/data') / name); cal = f.cal_for(name); T = lab_frame(cal)
    lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])
    sig = dot_sigma_px(cal, T, float(ds.settings.dot_diameter))
    views = ds.rig.split_views(np.asarray(ds[0].image)); tr = ds.truth(0); t = np.asarray(tr['uv'])
    rest = np.vstack([f.mesh.vertices[f.mesh.markers], f.mesh.nose])
    for floors in ((0.05, 0.08), (0.08, 0.05), (0.05, 0.05)):
        d = [detect_dots(views[v], DotSettings(sigma=sig, min_contrast=floors[v]))[0] for v in range(2)]
        X, _ = stereo_candidates(d[0], d[1], lab.views, 1.0)
        for reach in (40.0, 80.0):
            m = repose_layout(d[0], d[1], lab.views, rest, reach=reach)
            if m is None:
                print(name, floors, reach, 'None', len(X)); continue
            e = [np.linalg.norm(cam.project(m) - t[v], axis=1) for v, cam in enumerate(lab.views)]
            e0 = [np.linalg.norm(cam.project(rest) - t[v], axis=1) for v, cam in enumerate(lab.views)]
            print(name, floors, reach, f'cands {len(X)}  layout err px median rest {np.median(e0[0]):.1f}/{np.median(e0[1]):.1f} -> reposed {np.median(e[0]):.1f}/{np.median(e[1]):.1f}')
