"""First-frame stage with the subject's layout estimated from main's reconstruction (median of its normalised
markers, aligned to the model's rest by a similarity). usage: ff2.py OUT.jsonl STEP SET..."""
import sys, os, json, numpy as np
sys.path.insert(0, "/work/b35")
from ffh import setup
from lipgen.recon.firstpose import first_frame
from lipgen.recon.stereo_init import _similarity_3d
from lipgen.recon.steps import expected_projections
from lipgen.recon.pipeline import Reconstruction
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen._threads import blas_threads


from sublay import subject_layout


out = open(sys.argv[1], "a"); step = int(sys.argv[2])
for path in sys.argv[3:]:
    name = os.path.basename(path.rstrip('/'))
    g = setup(path); ds = Dataset(path); names = g["names"]; t = load_truth(ds)
    rec = Reconstruction.load(f"/work/b35/rec/{name}.main.npz")
    rest, ok = subject_layout(g["rest_points"], rec)
    exp = expected_projections(g["cameras"], rest)
    shift = np.linalg.norm(rest - g["rest_points"], axis=1)
    for k in range(0, len(ds), step):
        views = g["rig"].split_views(np.asarray(ds[k].image))
        with blas_threads(1):
            inits, bad, found = first_frame(views, exp, g["settings"], g["cameras"], rest, names, g["layout_covariance"])
        uv = t["uv"][k]
        err = np.linalg.norm(np.stack(inits) - uv, axis=2); seen = np.isfinite(err)
        right = (seen & (err <= 3)).all(0); wrong = (seen & (err > 3)).any(0)
        print(json.dumps(dict(set=name, frame=k, right=int(right.sum()), wrong=int(wrong.sum()),
                              wrong_names=[names[i] for i in np.flatnonzero(wrong)],
                              layout_moved_mm=float(np.median(shift[:-1])))), file=out, flush=True)
