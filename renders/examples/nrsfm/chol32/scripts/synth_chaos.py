import sys, numpy as np
sys.path.insert(0, "/work/wt/map32/tests")
from test_nrsfm_completion import _low_rank
from lipgen.nrsfm.completion import complete_subspace
from lipgen.experiments.nrsfm_benchmarks import hide_points
for F, P, r, noise in [(40, 16, 9, 0.05), (40, 20, 12, 0.05), (30, 16, 10, 0.02), (40, 24, 15, 0.05)]:
    W = _low_rank(F, P, r, seed=3) + noise * np.random.default_rng(4).standard_normal((2 * F, P))
    mask = hide_points(F, P, "gaps")
    a, _, ia = complete_subspace(W, mask, r)
    b, _, ib = complete_subspace(W * (1 + 1e-14 * np.random.default_rng(5).standard_normal(W.shape)), mask, r)
    hid = np.repeat(~mask, 2, axis=0)
    print(F, P, r, "hidden", int((~mask).sum()), "steps", ia["steps"], ib["steps"], "fill diff", f"{np.abs(a - b)[hid].max():.2e}", "W max", f"{np.abs(W).max():.2f}")
