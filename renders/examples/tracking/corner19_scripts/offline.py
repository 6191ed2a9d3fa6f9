"""Score a candidate by applying the lost-neighbour pass to main's saved tracks (the pass is the last step
of track_raw_frames, after take_back_out_of_place; main saves the tracks after that step).

usage: PYTHONPATH=/work/wt/corner19 python offline.py TAG RATIO NEITHER|none SET [SET ...]
Reads /work/corner19/out/main/SET.npz, writes /work/corner19/out/TAG/SET.json (+ npz). Truth read only to score.
"""
import json
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from lipgen._threads import blas_threads
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import accepted_sightings, load_truth
from lipgen.fem import Physics
from lipgen.recon.layoutprior import physics_layout_covariance
from lipgen.recon.lostneighbour import take_back_lost_neighbour
from lipgen.recon.modelmesh import model_mesh
from lipgen.recon.pipeline import lab_frame
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.steps import triangulate_tracks
from lipgen.recon.track import LOST
from lipgen.recon.tracks import Tracks
from lipgen.rig.camera import VIEWS

sys.path.insert(0, "/work/corner19")
from trackscore import DATA, ROOT, calibration, line  # noqa: E402

_COV = {}


def run(tag, name, ratio, neither):
    ds = Dataset(DATA / name)
    cal = calibration(name, ds)
    T = lab_frame(cal)
    lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])
    mesh = model_mesh("lip_mesh(0)")
    marks_rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose])
    names = [*mesh.marker_names, "nose"]
    if "cov" not in _COV:
        with blas_threads(1):
            _COV["cov"] = physics_layout_covariance(Physics(mesh))
    m = np.load(ROOT / "out" / "main" / f"{name}.npz")
    tracks = tuple(Tracks(m["uv"][v], m["status"][v] != LOST, m["status"][v],
                          np.full(m["status"][v].shape, np.nan), m["rejected"][v]) for v in range(2))
    c0 = time.process_time()
    with blas_threads(1):
        tracks, taken = take_back_lost_neighbour(tracks, lab.views, marks_rest, _COV["cov"], ratio, neither, names)
    cpu = time.process_time() - c0
    settings = ReconstructSettings()
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
    F = uv.shape[1]
    main = json.loads((ROOT / "out" / "main" / f"{name}.json").read_text())
    out = {"set": name, "tag": tag, "frames": F, "cpu_ms_per_frame": main["cpu_ms_per_frame"] + 1000 * cpu / F,
           "pass_cpu_ms_per_frame": 1000 * cpu / F, "load": open("/proc/loadavg").read().split()[:3],
           "ratio": ratio, "neither": neither, "max_gap_mm": max_gap,
           "taken": {names[i]: int(n) for i, n in enumerate(taken.sum(0)) if n}}
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
    np.savez_compressed(od / f"{name}.npz", uv=uv, status=np.stack([t.status for t in tracks]),
                        rejected=np.stack([t.rejected for t in tracks]), vis=vis, gap=gap, accepted=accepted,
                        points=points, taken=taken)
    (od / f"{name}.json").write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    tag, ratio, neither, sets = sys.argv[1], float(sys.argv[2]), sys.argv[3], sys.argv[4:]
    neither = None if neither == "none" else float(neither)
    for s in sets:
        o = run(tag, s, ratio, neither)
        print(line(o), "taken", o["taken"], f"pass {o['pass_cpu_ms_per_frame']:.0f} ms/frame", flush=True)
