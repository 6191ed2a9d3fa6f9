"""Cache dai K=auto's candidate runs per case (lip views from /work/lips, bodies by seed) for cheap
consensus variants."""
import sys, pickle, os, numpy as np
import lipgen.nrsfm.kchoice as kc
from lipgen.nrsfm import reconstruct

captured = {}
orig = kc.consensus_reconstruction
def spy(runs, chosen, *a, **k):
    captured["runs"], captured["chosen"] = runs, chosen
    return orig(runs, chosen, *a, **k)
kc.consensus_reconstruction = spy

def run(W, S, name):
    out = f"{CACHE}/{name.replace(' ', '_')}.pkl"
    if os.path.exists(out):
        return
    vis = np.isfinite(W[::2]) & np.isfinite(W[1::2])
    captured.clear()
    rec = reconstruct(W, "auto", visible=None if vis.all() else vis)
    pickle.dump(dict(name=name, W=W, S=S, rec=rec, runs=captured.get("runs"), chosen=captured.get("chosen")),
                open(out, "wb"))
    print(name, flush=True)

CACHE = os.environ.get("CACHE", "cache")
os.makedirs(CACHE, exist_ok=True)
if sys.argv[1] == "lips":
    from lipgen.recon.pipeline import Reconstruction
    from lipgen.recon.track import LOST
    from lipgen.nrsfm import dataset_tracks
    for d in sys.argv[2:]:
        recon = Reconstruction.load(d + "/recon.npz")
        for view, v in (("virtual", 0), ("real", 1)):
            seen = np.isfinite(recon.uv[v]).all(axis=-1) & (recon.status[v] != LOST)
            keep = np.flatnonzero(seen.sum(0) >= 3)
            tr = dataset_tracks(d + "/dataset", view, uv=recon.uv[v], seen=seen, marks=keep)
            tt = dataset_tracks(d + "/dataset", view)
            run(tr["W"], tr["S"], f"{d.rstrip('/').split('/')[-1]} {view} tracks")
            run(tt["W"], tt["S"], f"{d.rstrip('/').split('/')[-1]} {view} truth")
elif sys.argv[1] == "mocap":
    from lipgen.nrsfm.mocap import mocap_set
    for seq in mocap_set():
        run(seq.W, seq.S, "mocap_" + seq.name)
elif sys.argv[1] == "bench":
    from lipgen.experiments.nrsfm_benchmarks import data_dir
    for name in ("drink", "jaws"):
        with np.load(data_dir() / f"{name}.npz") as d:
            run(d["W"], d["S"], "bench_" + name)
else:
    from lipgen.nrsfm.validation import human_sequence
    for s in sys.argv[2:]:
        seq = human_sequence(int(s), 80); run(seq.W, seq.S, f"body_{s}_{seq.name}")
