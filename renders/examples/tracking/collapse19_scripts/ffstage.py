"""First-frame stage only (track_raw_frames on frame 0), with the mirror's detector floor overridden.
usage: PYTHONPATH=tree python ffstage.py SET MC_MIRROR[,MC_MIRROR...]  (truth for diagnosis only)"""
import json, sys
from pathlib import Path
import numpy as np
import lipgen.recon.steps as steps
from lipgen.dataset.layout import Dataset
from lipgen.fem import Physics
from lipgen.recon.calibrate import RigCalibration
from lipgen.recon.dots import DotSettings, detect_dots
from lipgen.recon.layoutprior import physics_layout_covariance
from lipgen.recon.modelmesh import model_mesh
from lipgen.recon.pipeline import dot_sigma_px, lab_frame
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.track import TrackerSettings

mesh = model_mesh("lip_mesh(0)")
cov = physics_layout_covariance(Physics(mesh))

def cal_for(name):
    for p in (Path('/work/collapse19/calib')/f'{name}.json', Path('/work/hard17/calib')/f'{name}.json'):
        if p.exists():
            return RigCalibration.from_dict(json.loads(p.read_text()))

def stage(name, mc_mirror, frame=0, exp_override=None):
    ds = Dataset(Path('/work/data')/name)
    cal = cal_for(name)
    T = lab_frame(cal)
    lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])
    sigma = dot_sigma_px(cal, T, float(ds.settings.dot_diameter))
    import os
    settings = ReconstructSettings(tracker=TrackerSettings(dots=DotSettings(sigma=sigma)), **json.loads(os.environ.get('FF_EXTRA', '{}')))
    calls = []
    def det(img, st):
        calls.append(1)
        if len(calls) == 1 and mc_mirror is not None:
            st = DotSettings(**{**st.__dict__, 'min_contrast': mc_mirror})
        return detect_dots(img, st)
    steps.detect_dots = det
    rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose])
    exp = steps.expected_projections(lab.views, rest) if exp_override is None else exp_override
    tracks = steps.track_raw_frames(iter([ds[frame].image]), ds.rig, exp, settings, cameras=lab.views,
                                    names=[*mesh.marker_names, 'nose'], rest_points=rest, layout_covariance=cov)
    tr = ds.truth(frame)
    right, wrong = [], []
    for v in range(2):
        uv = tracks[v].uv[0]
        err = np.linalg.norm(uv - np.asarray(tr['uv'])[v], axis=1)
        right.append(err < 1.5); wrong.append(np.isfinite(err) & (err >= 3))
    return (int((right[0] & right[1]).sum()), int(right[0].sum()), int(wrong[0].sum()), int(right[1].sum()),
            int(wrong[1].sum()))

if __name__ == '__main__':
    name = sys.argv[1]
    frame = int(sys.argv[3]) if len(sys.argv) > 3 else 0
    for mc in sys.argv[2].split(','):
        m = None if mc == 'main' else float(mc)
        b, r0, w0, r1, w1 = stage(name, m, frame)
        print(f'{name} f{frame} mirror floor {mc:5s}: right in both {b:2d}; mirror right/wrong {r0}/{w0}; direct {r1}/{w1}', flush=True)

def pre_check(name, mc_mirror=None, frame=0):
    """Each view's 2-D matches before check_first_frame: right / wrong counts, and the layout offset."""
    import lipgen.recon.steps as S
    got = {}
    orig = S.check_first_frame
    def spy(inits, found, *a, **k):
        got['inits'] = [u.copy() for u in inits]; got['found'] = found
        out = orig(inits, found, *a, **k)
        got['out'] = out
        return out
    S.check_first_frame = spy
    stage(name, mc_mirror, frame)
    S.check_first_frame = orig
    ds = Dataset(Path('/work/data')/name)
    tr = ds.truth(frame)
    for v in range(2):
        t = np.asarray(tr['uv'])[v]
        e = np.linalg.norm(got['inits'][v] - t, axis=1)
        print(f'  view {v}: {len(got["found"][v])} dots; matched {int(np.isfinite(e).sum())}, right {int((e<1.5).sum())}, wrong {int((e>=3).sum())}; errs', np.round(e, 1))
    return got

def picture(name, out, mc_mirror=None, frame=0):
    import matplotlib; matplotlib.use('Agg'); import matplotlib.pyplot as plt
    got = pre_check(name, mc_mirror, frame)
    ds = Dataset(Path('/work/data')/name)
    cal = cal_for(name); T = lab_frame(cal); lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])
    rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose]); exp = steps.expected_projections(lab.views, rest)
    views = ds.rig.split_views(np.asarray(ds[frame].image)); tr = ds.truth(frame)
    fig, ax = plt.subplots(1, 2, figsize=(16, 8))
    for v in range(2):
        t = np.asarray(tr['uv'])[v]
        ax[v].imshow(views[v]); f = got['found'][v]
        ax[v].plot(f[:, 0], f[:, 1], 'c+', ms=6)
        ax[v].plot(t[:, 0], t[:, 1], 'o', mfc='none', mec='lime', ms=9)
        ax[v].plot(exp[v][:, 0], exp[v][:, 1], 's', mfc='none', mec='b', ms=7)
        m = got['inits'][v]; ax[v].plot(m[:, 0], m[:, 1], 'x', color='orange', ms=8)
        allp = np.vstack([t, exp[v], m[np.isfinite(m[:, 0])]])
        lo, hi = np.nanmin(allp, 0) - 30, np.nanmax(allp, 0) + 30
        ax[v].set_xlim(lo[0], hi[0]); ax[v].set_ylim(hi[1], lo[1]); ax[v].set_title(f'{name} f{frame} view {v}')
    fig.tight_layout(); fig.savefig(out, dpi=70)
