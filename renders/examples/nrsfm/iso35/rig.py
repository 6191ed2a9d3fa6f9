"""Prototype: a truth-free isometry criterion for depth vs flat (issue 19). Development bodies only.
For each body: main's reconstruct(W, 'auto'); C(a) = mean over point pairs of var_t(d_ij) / mean_t(d_ij)^2
for depth scaled by a in [0, 1]; e3D(a) from the truth. usage: rig.py OUT.jsonl SEED..."""
import sys, json, numpy as np
from lipgen.nrsfm import reconstruct, e3d, flat_e3d
from lipgen.nrsfm.validation import human_sequence
from lipgen._threads import blas_threads

A = np.linspace(0, 1.2, 13)


def crit(S, q=1.0):
    """S (F, 3, P). Mean over the most stable fraction q of pairs of the squared coefficient of variation."""
    d = np.linalg.norm(S[:, :, :, None] - S[:, :, None, :], axis=1)   # (F, P, P)
    iu = np.triu_indices(S.shape[2], 1)
    d = d[:, iu[0], iu[1]]
    cv2 = d.var(0) / np.maximum(d.mean(0) ** 2, 1e-300)
    cv2 = np.sort(cv2)[: max(1, int(q * len(cv2)))]
    return float(cv2.mean())


out = open(sys.argv[1], "a")
for seed in map(int, sys.argv[2:]):
    seq = human_sequence(seed, n_frames=80)
    with blas_threads(1):
        rec = reconstruct(seq.W, "auto")
    S = np.asarray(rec.shapes, float)   # (F, 3, P) camera frame
    S = S - S.mean(2, keepdims=True)
    row = {"seed": seed, "k": int(rec.k), "supported": bool(rec.depth_supported), "flat": flat_e3d(seq.W, seq.S)}
    for q in (1.0, 0.5, 0.2):
        row[f"C{q}"] = [crit(np.concatenate([S[:, :2], a * S[:, 2:]], 1), q) for a in A]
    row["e3d"] = [e3d(S_est=np.concatenate([S[:, :2], a * S[:, 2:]], 1), S_true=seq.S) for a in A]
    print(json.dumps(row), file=out, flush=True)
