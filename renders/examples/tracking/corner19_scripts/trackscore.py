"""Track + triangulate datasets and score the sightings (lipgen reconstruct's steps up to triangulation).

usage: PYTHONPATH=<tree> python trackscore.py TAG SET [SET ...]   (SET like hard_s35)
Writes /work/corner19/out/TAG/SET.npz (tracks, gaps, visibility) and SET.json (scores).
Calibration: cached in /work/corner19/calib/SET.json; made once with the tree at /work/corner19/base (main).
Settings overrides: env H17_SETTINGS='{"field": value, ...}' (ReconstructSettings fields);
env H18_DOTS='{"relative": true, "min_contrast": 0.12}' (DotSettings fields of the tracker's detector).
Truth is read only after tracking, to score.
"""
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

import lipgen
from lipgen._threads import blas_threads
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import accepted_sightings, load_truth
from lipgen.fem import Physics
from lipgen.recon.calibrate import RigCalibration
from lipgen.recon.dots import DotSettings
from lipgen.recon.layoutprior import physics_layout_covariance
from lipgen.recon.modelmesh import model_mesh
from lipgen.recon.pipeline import dot_sigma_px, lab_frame
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.steps import expected_projections, track_raw_frames, triangulate_tracks
from lipgen.recon.track import TrackerSettings
from lipgen.rig.camera import VIEWS

ROOT = Path("/work/corner19")
DATA = Path("/work/data")


def calibration(name, ds):
    path = ROOT / "calib" / f"{name}.json"
    if path.exists():
        return RigCalibration.from_dict(json.loads(path.read_text()))
    if not str(Path(lipgen.__file__).resolve()).startswith("/work/corner19/base"):
        raise SystemExit(f"no cached calibration for {name}: make it with PYTHONPATH={ROOT}/base first")
    from lipgen.recon.calibcache import calibrated
    cal = calibrated([c.image for c in ds.calibration()], ds.rig, ds.calibration_boards())
    path.parent.mkdir(exist_ok=True)
    path.write_text(json.dumps(cal.to_dict()))
    return RigCalibration.from_dict(json.loads(path.read_text()))  # the same round trip as later runs


_COV = {}


def run(tag, name):
    d = DATA / name
    # hard 59-64 have no per-set .done (checked 21:50 UTC, against the brief); the generator's batch flag stands in
    batch = Path("/work/data/gen_59_64.done") if name in {f"hard_s{k}" for k in range(59, 65)} else None
    if not ((d / ".done").exists() or (batch is not None and batch.exists())):
        raise SystemExit(f"{d} not finished (.done missing)")
    ds = Dataset(d)
    cal = calibration(name, ds)
    T = lab_frame(cal)
    lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])
    mesh = model_mesh("lip_mesh(0)")
    sigma = dot_sigma_px(cal, T, float(ds.settings.dot_diameter))
    dots_extra = json.loads(os.environ.get("H18_DOTS", "{}"))
    settings = ReconstructSettings(tracker=TrackerSettings(dots=DotSettings(sigma=sigma, **dots_extra)))
    extra = json.loads(os.environ.get("H17_SETTINGS", "{}"))
    if extra:
        settings = replace(settings, **extra)
    marks_rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose])
    expected = expected_projections(lab.views, marks_rest)
    names = [*mesh.marker_names, "nose"]
    if "cov" not in _COV:
        with blas_threads(1):
            _COV["cov"] = physics_layout_covariance(Physics(mesh))
    frames = [f.image for f in ds]
    c0, w0 = time.process_time(), time.perf_counter()
    with blas_threads(1):
        tracks = track_raw_frames(iter(frames), ds.rig, expected, settings, cameras=lab.views, names=names,
                                  rest_points=marks_rest, layout_covariance=_COV["cov"])
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    gap_limit = settings.ray_gap_limit(lab.views)
    _, gap_all, _ = triangulate_tracks(lab.views, tracks)
    gap_limit.add(gap_all[gap_all <= settings.max_ray_gap])
    max_gap = gap_limit.limit()
    points, gap, vis = triangulate_tracks(lab.views, tracks, max_gap)
    P = len(mesh.markers)
    recon = SimpleNamespace(visible=vis[:, :P], ray_gap=gap, info={"ray_gap_limit_mm": max_gap})
    accepted = accepted_sightings(recon)
    truth = load_truth(ds)
    uv = np.stack([t.uv for t in tracks])
    status = np.stack([t.status for t in tracks])
    out = {"set": name, "tag": tag, "frames": len(frames), "cpu_ms_per_frame": 1000 * cpu / len(frames),
           "wall_ms_per_frame": 1000 * wall / len(frames), "load": open("/proc/loadavg").read().split()[:3],
           "lipgen": str(Path(lipgen.__file__).parent), "settings_extra": extra, "dots_extra": dots_extra, "max_gap_mm": max_gap}
    tot = {"visible": 0, "accepted": 0, "within": 0, "over": 0}
    for v, view in enumerate(VIEWS):
        truly = truth["visible"][:, v]
        err = np.linalg.norm(uv[v] - truth["uv"][:, v], axis=-1)
        ok = truly & accepted
        n_ok = int(ok.sum())
        over = int((err[ok] > 3).sum())
        out[view] = {"visible": int(truly.sum()), "accepted": n_ok, "within": n_ok - over, "over": over,
                     "rms_px": float(np.sqrt(np.mean(err[ok] ** 2))) if n_ok else float("nan")}
        for k in tot:
            tot[k] += out[view][k]
    out["all"] = tot
    out["accepted_pct"] = 100 * tot["accepted"] / max(tot["visible"], 1)
    out["within_pct"] = 100 * tot["within"] / max(tot["visible"], 1)
    od = ROOT / "out" / tag
    od.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(od / f"{name}.npz", uv=uv, status=status,
                        rejected=np.stack([t.rejected for t in tracks]), vis=vis, gap=gap, accepted=accepted,
                        points=points)
    (od / f"{name}.json").write_text(json.dumps(out, indent=1))
    return out


def line(o):
    m, r = o[VIEWS[0]], o[VIEWS[1]]
    return (f"{o['set']:12s} {o['accepted_pct']:5.1f} / {o['within_pct']:5.1f} / {o['all']['over']:3d}  "
            f"rms {m['rms_px']:.2f} / {r['rms_px']:.2f}  cpu {o['cpu_ms_per_frame']:.0f} ms/frame  "
            f"load {o['load'][0]}")


if __name__ == "__main__":
    tag, sets = sys.argv[1], sys.argv[2:]
    for s in sets:
        print(line(run(tag, s)), flush=True)
