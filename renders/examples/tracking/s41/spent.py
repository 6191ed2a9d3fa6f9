"""One spent set with its memoised reconstruction and calibration (truth read: development only), for the s41
diagnostics: spent(ROOT, SET, VARIANT) -> dict, or None when ROOT/cache has no calibration for SET."""
import os, pickle, numpy as np
from dataclasses import replace
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, accepted_sightings
from lipgen.recon.pipeline import Reconstruction, dot_sigma_px, lab_frame
from lipgen.recon.settings import ReconstructSettings


def spent(root, name, var):
    """ds, truth, rec, acc (F, P+1), tuv (2, F, P+1, 2), err (2, F, P+1) px, cal, T (lab frame), dots settings."""
    if not os.path.exists(f"{root}/cache/{name}.calib.pkl"):
        return None
    ds = Dataset(f"/work/sets/{name}"); t = load_truth(ds)
    rec = Reconstruction.load(f"{root}/rec/{name}.{var}.npz")
    acc = accepted_sightings(rec); tuv = np.moveaxis(t["uv"], 1, 0)
    with open(f"{root}/cache/{name}.calib.pkl", "rb") as fh:
        cal = pickle.load(fh)
    T = lab_frame(cal)
    dots = replace(ReconstructSettings().tracker.dots, sigma=dot_sigma_px(cal, T, float(ds.settings.dot_diameter)))
    return dict(ds=ds, truth=t, rec=rec, acc=acc, tuv=tuv, err=np.linalg.norm(rec.uv - tuv, axis=-1), cal=cal,
                T=T, dots=dots)
