"""Consensus restricted to Ks within R times the least rotation roughness: e3D per R (dev harness).

'flat' here is the reconstruction itself with zero depth (shrink_depth(rec, 0)): its x, y are the tracks,
with the method's own completion where a mark was not seen (lipgen evaluate's flat_e3d fills those from the
truth's projections instead; the two differ only where marks are missing)."""
import sys, json, numpy as np
import lipgen.nrsfm.kchoice as kc
from lipgen.nrsfm import reconstruct
from lipgen.nrsfm.consensus import consensus_reconstruction
from lipgen.nrsfm.kchoice import shrink_depth
from lipgen.nrsfm.metrics import e3d
from lipgen.nrsfm.plausibility import rotation_roughness

RS = [np.inf, 100, 30, 10, 5, 3]
captured = {}
orig = kc.consensus_reconstruction
def spy(runs, chosen, m, rho, roughness_ratio=None):
    captured["runs"], captured["chosen"] = runs, chosen
    return orig(runs, chosen, m, rho, roughness_ratio)
kc.consensus_reconstruction = spy

def run(W, S, name):
    vis = np.isfinite(W[::2]) & np.isfinite(W[1::2])
    captured.clear()
    rec = reconstruct(W, "auto", visible=None if vis.all() else vis)
    out = dict(name=name, k=int(rec.k), flat=round(e3d(S_est=shrink_depth(rec, 0.0).S, S_true=S), 4),
               auto=round(e3d(S_est=rec.S, S_true=S), 4), supported=rec.depth_supported)
    if "runs" in captured and rec.depth_supported:
        runs, ch = captured["runs"], captured["chosen"]
        rough = np.array([rotation_roughness(r.rotations) for r in runs])
        out["single"] = round(e3d(S_est=runs[ch].S, S_true=S), 4)
        out["rough_ratio"] = [round(float(x), 1) for x in sorted(rough / rough.min())][:5]
        for R in RS:   # the library's filter (the runs of this session used the same rule written here)
            r2 = consensus_reconstruction(runs, ch, roughness_ratio=R)
            out[f"R{R}"] = round(e3d(S_est=r2.S, S_true=S), 4)
    print(json.dumps(out), flush=True)

if __name__ == "__main__":
    if sys.argv[1] == "lips":
        from lipgen.recon.pipeline import Reconstruction
        from lipgen.recon.track import LOST
        from lipgen.nrsfm import dataset_tracks
        for d in sys.argv[2:]:
            recon = Reconstruction.load(d + "/recon.npz")
            for view, v in (("virtual", 0), ("real", 1)):
                seen = np.isfinite(recon.uv[v]).all(axis=-1) & (recon.status[v] != LOST)
                keep = np.flatnonzero(seen.sum(0) >= 3)   # as the report: marks tracked in 3+ frames
                tr = dataset_tracks(d + "/dataset", view, uv=recon.uv[v], seen=seen, marks=keep)
                tt = dataset_tracks(d + "/dataset", view)
                run(tr["W"], tr["S"], f"{d.split('/')[-1]} {view} tracks")
                run(tt["W"], tt["S"], f"{d.split('/')[-1]} {view} truth")
    elif sys.argv[1] == "mocap":
        from lipgen.nrsfm.mocap import mocap_set
        for seq in mocap_set():
            run(seq.W, seq.S, seq.name)
    elif sys.argv[1] == "bench":
        from lipgen.experiments.nrsfm_benchmarks import data_dir
        for name in ("drink", "jaws"):
            with np.load(data_dir() / f"{name}.npz") as d:
                run(d["W"], d["S"], name)
    else:
        from lipgen.nrsfm.validation import human_sequence
        for s in sys.argv[2:]:
            seq = human_sequence(int(s), 80); run(seq.W, seq.S, seq.name)
