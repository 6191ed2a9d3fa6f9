"""The dumps dump.py wrote, with each set's true projections (truth read: spent sets only):
for name, (a, b, disputed, cams, rest, cov, verdict), tuv in dumped(DUMP, names): ...  tuv: (2, F, P + 1, 2) px.
Sets with nothing disputed are skipped."""
import pickle, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth


def dumped(folder, names):
    for name in names:
        with open(f"{folder}/{name}.arb.pkl", "rb") as fh:
            cap = pickle.load(fh)
        if cap is not None:
            yield name, cap, np.moveaxis(load_truth(Dataset(f"/work/sets/{name}"))["uv"], 1, 0)


def spans(disputed, m):
    """(start, stop) of each run of consecutive disputed frames of marker m."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], disputed[:, m].astype(int), [0]])))
    return list(zip(edges[::2], edges[1::2]))


def right_run(a, b, tuv, s, e, m, tol=3.0):
    """Which run's sightings of marker m in frames s..e-1 are all within tol px of the truth in both views:
    "A" (the first), "B" (the second), "both" or "neither"."""
    ea, eb = (max(np.nanmax(np.linalg.norm(run[v].uv[s:e, m] - tuv[v, s:e, m], axis=-1)) for v in range(2))
              for run in (a, b))
    return "A" if ea <= tol < eb else "B" if eb <= tol < ea else "both" if eb <= tol else "neither"
