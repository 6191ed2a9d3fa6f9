"""Issue 19 probe: split-half reliability of the depth (even frames against odd frames, no truth) as a shrink
factor toward flat. usage: half.py OUT.jsonl SEED..."""
import sys, json, numpy as np
from lipgen.nrsfm import reconstruct, e3d, flat_e3d
from lipgen.nrsfm.validation import human_sequence
from lipgen._threads import blas_threads


def cam_shapes(rec):
    S = np.asarray(rec.shapes, float)
    S = S.reshape(-1, 3, S.shape[-1]) if S.ndim == 2 else S
    return S - S.mean(2, keepdims=True)


def reliability(Se, So):
    n = min(len(Se), len(So))
    ze, zo = Se[:n, 2].ravel(), So[:n, 2].ravel()
    r = abs(np.corrcoef(ze, zo)[0, 1])
    return float(r)


out = open(sys.argv[1], "a")
for seed in map(int, sys.argv[2:]):
    seq = human_sequence(seed, n_frames=80)
    W = seq.W
    with blas_threads(1):
        full = reconstruct(W, "auto")
        k = int(full.k)
        ev = reconstruct(W.reshape(-1, 2, W.shape[1])[0::2].reshape(-1, W.shape[1]), k)
        od = reconstruct(W.reshape(-1, 2, W.shape[1])[1::2].reshape(-1, W.shape[1]), k)
    S = cam_shapes(full)
    rho = reliability(cam_shapes(ev), cam_shapes(od))
    alpha = min(1.0, max(0.0, 2 * rho / (1 + rho)))
    Sa = S.copy(); Sa[:, 2] *= alpha
    row = {"seed": seed, "k": k, "flat": flat_e3d(W, seq.S), "main": e3d(S_est=S, S_true=seq.S),
           "rho": rho, "alpha": alpha, "shrunk": e3d(S_est=Sa, S_true=seq.S)}
    print(json.dumps(row), file=out, flush=True)
