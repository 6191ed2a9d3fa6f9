import sys, numpy as np, logging
logging.disable(logging.WARNING)
sys.path.insert(0, '/work/main')
from lipgen.recon.pipeline import Reconstruction, model_mesh
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.displacement import displacement_error
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.rest import measured_markers
from lipgen.recon.restsource import rest_markers
for s in sys.argv[1:]:
    ds = Dataset(f"e{s}")
    for r in ("model", "recording"):
        rc = Reconstruction.load(f"e{s}_{r}.npz")
        mesh = model_mesh(rc.info["mesh_source"]); P = len(mesh.markers)
        rest = rest_markers(rc, mesh)
        truth = load_truth(ds)["marks_model"][:, :P]
        F = len(truth); tail = np.arange(F) >= F - 10
        m = measured_markers(rc)
        out = []
        for name, sel in (("training", ~tail), ("tail", tail)):
            mm = m & sel[:, None]
            d = displacement_error(rc.markers, mm, rest, truth, ds.rest_marks()[:P])
            out.append(f"{name} {d['rms_mm']:.2f} / offset {d['offset_rms_mm']:.2f}")
        print(s, r, rc.info["rest_source"].get("rest_frames"), "; ".join(out))
