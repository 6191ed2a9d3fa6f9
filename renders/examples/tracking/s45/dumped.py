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
