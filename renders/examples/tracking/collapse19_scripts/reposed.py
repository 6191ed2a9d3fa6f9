"""Truth-free: does first_frame_repose = 6 change frame 0's matches? (first_frame's output vs the off setting's)"""
import json, sys
from pathlib import Path
import numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.fem import Physics
from lipgen.recon.calibrate import RigCalibration
from lipgen.recon.dots import DotSettings
from lipgen.recon.firstpose import first_frame
from lipgen.recon.grow import _paired
from lipgen.recon.layoutprior import physics_layout_covariance
from lipgen.recon.modelmesh import model_mesh
from lipgen.recon.pipeline import dot_sigma_px, lab_frame
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.steps import expected_projections
from lipgen.recon.track import TrackerSettings

mesh = model_mesh("lip_mesh(0)")
cov = physics_layout_covariance(Physics(mesh))
rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose])
names = [*mesh.marker_names, 'nose']
for name in sys.argv[1:]:
    ds = Dataset(Path('/work/data') / name)
    cal = RigCalibration.from_dict(json.loads((Path('/work/collapse19/calib') / f'{name}.json').read_text()))
    T = lab_frame(cal); lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])
    dots = DotSettings(sigma=dot_sigma_px(cal, T, float(ds.settings.dot_diameter)))
    exp = expected_projections(lab.views, rest)
    views = ds.rig.split_views(np.asarray(ds[0].image))
    out = []
    for extra in ({}, {"first_frame_repose": 6}):
        st = ReconstructSettings(tracker=TrackerSettings(dots=dots), **extra)
        out.append(first_frame(views, exp, st, lab.views, rest, names, cov))
    same = all(np.array_equal(a, b, equal_nan=True) for a, b in zip(out[0][0], out[1][0])) and \
        np.array_equal(out[0][1], out[1][1]) and all(np.array_equal(a, b) for a, b in zip(out[0][2], out[1][2]))
    print(f'{name:11s} pairs off {int(_paired(out[0][0]).sum()):2d}  C3 {int(_paired(out[1][0]).sum()):2d}  '
          f'{"same" if same else "ACTS"}', flush=True)
