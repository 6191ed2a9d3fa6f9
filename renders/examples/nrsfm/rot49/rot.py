"""Issue 19 probe: is main's NRSfM worse than flat where its estimated view directions hardly spread?
usage: rot.py OUT.jsonl SEED...  (development bodies; truth read for e3D only)"""
import sys, json, numpy as np
from lipgen.nrsfm import reconstruct, e3d, flat_e3d
from lipgen.nrsfm.validation import human_sequence
from lipgen._threads import blas_threads


def spread_deg(R):
    R = np.asarray(R, float)
    d = np.cross(R[:, 0, :], R[:, 1, :])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    m = d.mean(0); m /= np.linalg.norm(m)
    ang = np.degrees(np.arccos(np.clip(d @ m, -1, 1)))
    return float(np.sqrt((ang ** 2).mean())), float(ang.max())


out = open(sys.argv[1], "a")
for seed in map(int, sys.argv[2:]):
    seq = human_sequence(seed, n_frames=80)
    with blas_threads(1):
        r = reconstruct(seq.W, "auto")
    S = np.asarray(r.shapes, float); S = S - S.mean(2, keepdims=True)
    R = np.asarray(r.rotations, float)
    rms, mx = spread_deg(R)
    row = {"seed": seed, "k": int(r.k), "flat": flat_e3d(seq.W, seq.S), "main": e3d(S_est=S, S_true=seq.S),
           "rms_deg": rms, "max_deg": mx, "rot_shape": list(R.shape)}
    print(json.dumps(row), file=out, flush=True)
