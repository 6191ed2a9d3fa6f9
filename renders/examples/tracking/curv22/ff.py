"""Frame 0 after the first-frame stage, main against a candidate: markers right (<= 3 px) in both views, wrong
(> 3 px in a view), unmatched. usage: python ff.py OUT.jsonl SWITCH SET...
SWITCH: joint (lipgen.recon.grow.JOINT; apply joint_labels.patch) or cap (lipgen.recon.firstpose.FIRST_FRAME_CAP;
apply first_frame_cap.patch). Rows: "joint": false for main, true for the candidate (either switch)."""
import sys, os, json, numpy as np
import lipgen.recon.firstpose as firstpose
import lipgen.recon.grow as grow
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from frame0 import frame0


out = open(sys.argv[1], 'a')
module, flag = {"joint": (grow, "JOINT"), "cap": (firstpose, "FIRST_FRAME_CAP")}[sys.argv[2]]
for path in sys.argv[3:]:
    ds = Dataset(path); names = list(ds.marks)
    for on in (False, True):
        setattr(module, flag, on)
        got, _ = frame0(path)
        t = load_truth(ds)
        err = np.linalg.norm(got - t['uv'][0], axis=2)    # (2, P) virtual, real
        seen = np.isfinite(err)
        right = (seen & (err <= 3)).all(0)
        wrong = (seen & (err > 3)).any(0)
        row = dict(set=os.path.basename(path.rstrip('/')), joint=on, right=int(right.sum()), wrong=int(wrong.sum()),
                   wrong_names=[names[i] for i in np.flatnonzero(wrong)],
                   unmatched=[names[i] for i in np.flatnonzero(~seen.all(0) & ~wrong)])
        print(json.dumps(row), file=out, flush=True)
