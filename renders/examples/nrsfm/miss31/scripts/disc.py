import sys, numpy as np
import lipgen.nrsfm.completion as C
from lipgen.nrsfm.validation import human_sequence
from lipgen.experiments.nrsfm_benchmarks import hide_points
from lipgen.nrsfm._tracks import check_tracks
from lipgen.nrsfm.engine import _normalise_scale
seq = human_sequence(1709, 80); F, P = seq.W.shape[0] // 2, seq.W.shape[1]
vis = hide_points(F, P, "gaps"); W = seq.W.copy(); W[np.repeat(~vis, 2, axis=0)] = np.nan
tr = check_tracks(_normalise_scale(W, vis)[0], vis)
rows = np.arange(2 * F).reshape(F, 2)[0::2].ravel()
half = check_tracks(tr.W[rows], tr.mask[0::2])
st = C.SubspaceCompletion(half.W, half.mask, 27); st.run(int(sys.argv[1]))
N, Y = st.N, st.Y
fr = st.frames
c0 = fr.evaluate(N)
rng = np.random.default_rng(1)
for eps in (0, 1e-14, 1e-12, 1e-10, 1e-8):
    Nn, Yn = C._bases(np.linalg.qr(N + eps * Y @ rng.standard_normal((Y.shape[1], N.shape[1])))[0])
    fr._last = None
    print(eps, fr.evaluate(Nn) / c0 - 1)
# per-group: conditioning of G
for idx, rowsg in fr.groups:
    h = idx.shape[1]
    if h:
        G = N[idx] @ N[idx].transpose(0, 2, 1); w = np.linalg.eigvalsh(G)
        print("h", h, "n", len(idx), "min cond", f"{(w[:, -1] / np.maximum(w[:, 0], 1e-300)).max():.2e}")
