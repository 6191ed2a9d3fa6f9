"""Issue 19 dev probe: does a second method's disagreement with main's depth flag main's wrong depths?
Development bodies only. usage: xm.py OUT.jsonl SEED..."""
import sys, json, time, numpy as np
from lipgen.nrsfm import reconstruct, e3d, flat_e3d
from lipgen.nrsfm.validation import human_sequence
from lipgen._threads import blas_threads

def shapes(rec):
    S = np.asarray(rec.shapes, float); return S - S.mean(2, keepdims=True)

out = open(sys.argv[1], "a")
for seed in map(int, sys.argv[2:]):
    seq = human_sequence(seed, n_frames=80)
    row = {"seed": seed, "flat": flat_e3d(seq.W, seq.S)}
    with blas_threads(1):
        t = time.process_time(); m = reconstruct(seq.W, "auto"); row["t_main"] = time.process_time() - t
        Sm = shapes(m); row["k"] = int(m.k); row["main"] = e3d(S_est=Sm, S_true=seq.S)
        others = {}
        for name, meth, k in (("pnd", "em-pnd", max(m.k - 1, 0)), ("ppca", "em-ppca", max(m.k - 1, 0)),
                              ("daiK", "dai", m.k), ("pndauto", "em-pnd", "auto")):
            t = time.process_time()
            try:
                r = reconstruct(seq.W, k, meth); S = shapes(r)
            except Exception as exc:
                row[name] = str(exc); continue
            row[name] = e3d(S_est=S, S_true=seq.S); row["t_" + name] = time.process_time() - t
            row["dis_" + name] = e3d(S_est=Sm, S_true=S); row["dis_rev_" + name] = e3d(S_est=S, S_true=Sm)
            flatS = np.concatenate([S[:, :2], 0 * S[:, 2:]], 1)
            row["flatdis_" + name] = e3d(S_est=flatS, S_true=S)
    print(json.dumps(row), file=out, flush=True)
