"""s40_examples.png: three development markers' error (px, direct view) per accepted frame, main against the
split (reconstructions from run.py in /work/b40/rec). Truth read here, after the tracking, for the picture only."""
import numpy as np
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, accepted_sightings
from lipgen.recon.pipeline import Reconstruction

CASES = [("hard172", "upper_corner_right"), ("hard196", "corner_left"), ("hard198", "upper_corner_left")]
fig, axes = plt.subplots(1, 3, figsize=(12, 3.2), sharey=True)
for ax, (name, marker) in zip(axes, CASES):
    t = load_truth(Dataset(f"/work/sets/{name}"))
    for var, label, style in (("W", "main", "o"), ("S5", "split (5 px)", "x")):
        rec = Reconstruction.load(f"/work/b40/rec/{name}.{var}.npz")
        k = rec.info["marker_names"].index(marker)
        acc = accepted_sightings(rec)[:, k]
        err = np.linalg.norm(rec.uv[1, :, k] - t["uv"][:, 1, k], axis=-1)
        f = np.flatnonzero(acc)
        ax.plot(f, err[f], style, label=label, ms=5 if style == "o" else 6, mfc="none" if style == "o" else None)
    ax.axhline(3, color="grey", lw=0.8, ls="--")
    ax.set_title(f"{name}: {marker}", fontsize=10)
    ax.set_xlabel("frame")
axes[0].set_ylabel("accepted sighting's error, direct view (px)")
axes[0].legend(fontsize=8)
fig.tight_layout()
fig.savefig("s40_examples.png", dpi=110)
