"""Frame 0 of hard 56 / 58 / 64, both views: truth (green), layout at rest (blue), re-posed layout (magenta),
dots at the fixed floor 0.08 (cyan +) and the extra ones at 0.05 (yellow .)."""
import json, sys
from pathlib import Path
import numpy as np
import matplotlib; matplotlib.use('Agg'); import matplotlib.pyplot as plt
from lipgen.dataset.layout import Dataset
from lipgen.recon.calibrate import RigCalibration
from lipgen.recon.dots import DotSettings, detect_dots
from lipgen.recon.modelmesh import model_mesh
from lipgen.recon.pipeline import dot_sigma_px, lab_frame
from lipgen.recon.stereo_init import repose_layout
mesh = model_mesh("lip_mesh(0)"); rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose])
sets = sys.argv[2:]
fig, ax = plt.subplots(2, len(sets), figsize=(6 * len(sets), 11))
for j, name in enumerate(sets):
    ds = Dataset(Path('/work/data') / name)
    cal = RigCalibration.from_dict(json.loads((Path('/work/collapse19/calib') / f'{name}.json').read_text()))
    T = lab_frame(cal); lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])
    sig = dot_sigma_px(cal, T, float(ds.settings.dot_diameter))
    views = ds.rig.split_views(np.asarray(ds[0].image)); t = np.asarray(ds.truth(0)['uv'])
    hi = [detect_dots(v, DotSettings(sigma=sig))[0] for v in views]
    lo = [detect_dots(v, DotSettings(sigma=sig, min_contrast=0.05))[0] for v in views]
    moved = repose_layout(lo[0], lo[1], lab.views, rest)
    for v in range(2):
        a = ax[v, j]; a.imshow(views[v])
        a.plot(lo[v][:, 0], lo[v][:, 1], '.', color='yellow', ms=3)
        a.plot(hi[v][:, 0], hi[v][:, 1], 'c+', ms=7)
        a.plot(t[v][:, 0], t[v][:, 1], 'o', mfc='none', mec='lime', ms=10)
        e = lab.views[v].project(rest); a.plot(e[:, 0], e[:, 1], 's', mfc='none', mec='blue', ms=7)
        if moved is not None:
            m = lab.views[v].project(moved); a.plot(m[:, 0], m[:, 1], 'D', mfc='none', mec='magenta', ms=7)
        allp = np.vstack([t[v], e]); lo_, hi_ = allp.min(0) - 20, allp.max(0) + 20
        a.set_xlim(lo_[0], hi_[0]); a.set_ylim(hi_[1], lo_[1])
        a.set_title(f'{name} frame 0, {"mirror" if v == 0 else "direct"}'); a.set_xticks([]); a.set_yticks([])
fig.tight_layout(); fig.savefig(sys.argv[1], dpi=60)
