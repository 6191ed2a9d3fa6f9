"""Truth-free: each view's first-frame floor under first_frame_floor = r (None: not lowered). Frame 0 only.
usage: PYTHONPATH=tree python floors.py SET...   (cached calibrations only)"""
import json, sys
from pathlib import Path
import numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.recon.calibrate import RigCalibration
from lipgen.recon.dots import DotSettings, detect_dots
from lipgen.recon.firstframe import _view_floor
from lipgen.recon.modelmesh import model_mesh
from lipgen.recon.pipeline import dot_sigma_px, lab_frame
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.steps import expected_projections

mesh = model_mesh("lip_mesh(0)")
for name in sys.argv[1:]:
    ds = Dataset(Path('/work/data') / name)
    cal = RigCalibration.from_dict(json.loads((Path('/work/collapse19/calib') / f'{name}.json').read_text()))
    T = lab_frame(cal); lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])
    dots = DotSettings(sigma=dot_sigma_px(cal, T, float(ds.settings.dot_diameter)))
    st = ReconstructSettings()
    exp = expected_projections(lab.views, np.vstack([mesh.vertices[mesh.markers], mesh.nose]))
    views = ds.rig.split_views(np.asarray(ds[0].image))
    cells = []
    for v, img in enumerate(views):
        uv, s = detect_dots(img, dots)
        for r in (0.7, 0.5):
            f = _view_floor(uv, s, exp[v], st.init_gate, st.robust_first_frame, st.first_frame_dark, r,
                            st.tracker.floor_min, dots.min_contrast)
            cells.append(f'v{v} r{r}: ' + ('-' if f is None else f'{f:.3f}'))
    print(f'{name:11s} ' + '  '.join(cells), flush=True)
