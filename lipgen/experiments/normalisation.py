"""The normalisation methods compared on exact world marks of generated subjects.

For each seed, the subject and head motion that ``lipgen generate --seed S`` would render
(:func:`lipgen.dataset.generate` without the images) give the exact world marks and nose; each method of
:data:`lipgen.recon.normalize.METHODS` normalises them (reference frame ``"auto"``, as the pipeline),
and is scored against the true model-frame marks (mm RMS), by the least-strain fields
``Physics.reach`` builds from its markers against the true surface (mm RMS per node), and for
the pose methods by the head-rotation error (deg) against the true pose.

Run ``python -m lipgen.experiments.normalisation 0 1 2 3 4`` (about 5 s per seed).
"""

from __future__ import annotations

import sys

import numpy as np

__all__ = ["compare_normalisations", "action_bias_deg"]


def _rms(x) -> float:
    return float(np.sqrt(np.nanmean(np.sum(np.asarray(x) ** 2, axis=-1))))


def compare_normalisations(seeds=(0, 1, 2, 3, 4), frames: int = 150, methods=None) -> dict:
    """``{method: {"norm_mm": [...], "fields_mm": [...], "pose_deg_rms": [...], "pose_deg_max": [...]}}``
    with one entry per seed; ``"floor"`` holds the reach from the true markers."""
    from lipgen.dataset.layout import GenerateSettings
    from lipgen.dataset.simulation import simulate_motion as _simulate
    from lipgen.fem import Physics
    from lipgen.mesh.procedural import lip_mesh
    from lipgen.recon.headpose import rotation_vector
    from lipgen.recon.normalize import METHODS, lip_subsets, normalize_markers
    from lipgen.recon.steps import reach_fields

    mesh = lip_mesh(0)
    physics = Physics(mesh)
    M = mesh.vertices[mesh.markers]
    upper, lower = lip_subsets(mesh.marker_names)
    P = len(M)
    out: dict = {}
    for seed in seeds:
        motion = _simulate(GenerateSettings(frames=frames, seed=int(seed)))
        true = motion.markers
        true_fields = motion.vertices[:, :mesh.n_nodes] - mesh.vertices
        every = np.ones((frames, P), bool)

        def fields_rms(markers, every=every, true_fields=true_fields):
            f = reach_fields(physics, markers - M, every, mesh.markers)
            return float(np.sqrt(np.mean(np.sum((f - true_fields) ** 2, axis=-1))))

        for method in methods or METHODS:
            n = normalize_markers(motion.markers_world, motion.nose_world, upper, lower, M,
                                  model_nose=mesh.nose, reference_frame="auto", method=method,
                                  physics=physics)
            row = out.setdefault(method, {"norm_mm": [], "fields_mm": [], "pose_deg_rms": [],
                                          "pose_deg_max": [], "outliers": []})
            row["norm_mm"].append(_rms(n.markers - true))
            row["fields_mm"].append(fields_rms(n.markers))
            if method != "thesis":
                # data -> model rotation per frame, against the inverse of the true head rotation
                R = np.einsum("ij,fjk->fik", n.similarity.rotation, n.rotations)
                err = np.degrees(np.linalg.norm(rotation_vector(R @ motion.poses[:, :3, :3]), axis=-1))
                row["pose_deg_rms"].append(float(np.sqrt(np.mean(err ** 2))))
                row["pose_deg_max"].append(float(err.max()))
                row["outliers"].append(int(n.outliers.sum()))
        floor = out.setdefault("floor", {"fields_mm": [], "true_displacement_mm": []})
        floor["fields_mm"].append(fields_rms(true))
        floor["true_displacement_mm"].append(_rms(true_fields))
    return out


def action_bias_deg(kind: str = "force", seed: int = 0) -> dict:
    """Head rotation (deg, rotation vector x nod, y turn, z roll) that the pose method reads into
    each single action at activation 1 with the head still: its bias."""
    from lipgen.fem import Physics
    from lipgen.mesh.procedural import lip_mesh
    from lipgen.recon.headpose import MarkerMetric, least_cost_rotations, rotation_vector
    from lipgen.subject.motion import ACTIONS, default_subject

    mesh = lip_mesh(0)
    M, n0 = mesh.vertices[mesh.markers], mesh.nose
    metric = MarkerMetric.euclidean(len(M)) if kind == "euclidean" else \
        MarkerMetric.from_physics(Physics(mesh), kind)
    subject = default_subject(seed)
    U = subject.displacements(np.eye(len(ACTIONS)))[:, subject.mesh.markers]
    R, _, _ = least_cost_rotations(M + U - n0, M - n0, metric, np.ones((len(ACTIONS), len(M)), bool),
                                   np.eye(3))
    return dict(zip(ACTIONS, np.degrees(rotation_vector(R)).tolist(), strict=True))


def main(argv=None) -> int:
    seeds = [int(a) for a in (sys.argv[1:] if argv is None else argv)] or [0, 1, 2, 3, 4]
    res = compare_normalisations(seeds)
    w = sys.stdout.write
    w(f"seeds {seeds}, 150 frames, exact world marks; mean over seeds [per seed]\n")
    for method, row in res.items():
        cells = [f"{k} {np.mean(v):.3f} [{', '.join(f'{x:.2f}' for x in v)}]" for k, v in row.items() if v]
        w(f"{method:13s} " + "; ".join(cells) + "\n")
    for kind in ("force", "energy", "euclidean"):
        w(f"\nbias ({kind}), deg x y z |total| per action at activation 1:\n")
        for name, v in action_bias_deg(kind).items():
            w(f"  {name:28s} {v[0]:+.2f} {v[1]:+.2f} {v[2]:+.2f}  {np.linalg.norm(v):.2f}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
