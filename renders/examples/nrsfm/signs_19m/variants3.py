"""Sign alignment variant: signs that maximise the agreement |sum s_i z_i|^2 (chosen's sign fixed)."""
import glob, pickle, json, itertools, numpy as np
import lipgen.nrsfm.consensus as cs
from lipgen.nrsfm.consensus import consensus_reconstruction, _centred_depth
from lipgen.nrsfm.kchoice import shrink_depth
from lipgen.nrsfm.metrics import e3d
from lipgen.nrsfm.plausibility import rotation_roughness

def consensus_z(cands, chosen, m=4, mode="agree"):
    rough = np.array([rotation_roughness(c.rotations) for c in cands])
    order = [int(i) for i in np.argsort(rough, kind="stable") if i != chosen]
    picked = [chosen] + order[: m - 1]
    Z = np.stack([_centred_depth(cands[i]) for i in picked])
    xy = cands[chosen].shapes[:, :2]; xy = xy - xy.mean(axis=2, keepdims=True)
    zero = np.linalg.norm(Z[0]) < 1e-6 * np.linalg.norm(xy)
    if mode.startswith("hyb"):
        if not zero:
            mode = "main"
        elif mode == "hyb_next":
            mode = "next"
        else:
            mode = "agree"
    if mode == "main":
        Z = np.stack([z if np.sum(z * Z[0]) >= 0 else -z for z in Z])
    elif mode == "next":
        Z = np.stack([z if np.sum(z * Z[1]) >= 0 else -z for z in Z])
    if mode == "agree":
        best, bs = -1, None
        for s in itertools.product([1.0, -1.0], repeat=len(picked) - 1):
            sv = np.array((1.0,) + s)
            v = float(np.sum(np.tensordot(sv, Z, 1) ** 2))
            if v > best: best, bs = v, sv
        Z = Z * bs[:, None, None]
    elif mode == "largest":
        ref = Z[int(np.argmax([np.linalg.norm(z) for z in Z]))]
        Z = np.stack([z if np.sum(z * ref) >= 0 else -z for z in Z])
    zbar = Z.mean(0); power = float(np.sum(zbar ** 2))
    spread = float(np.sum((Z - zbar) ** 2)) / (len(picked) - 1) / len(picked) / power
    a = max(0.0, 1 - spread)
    return a * zbar, a

for f in sorted(glob.glob("cache/*.pkl")):
    d = pickle.load(open(f, "rb"))
    rec, runs, ch, S = d["rec"], d["runs"], d["chosen"], d["S"]
    row = dict(name=d["name"], flat=e3d(S_est=shrink_depth(rec, 0.0).S, S_true=S), auto=e3d(S_est=rec.S, S_true=S))
    if runs is not None and rec.depth_supported and rec.info.get("shapes") != "rank-K fit":
        for mode in ("main", "hyb_agree", "hyb_next"):
            z, a = consensus_z(runs, ch, mode=mode)
            row[mode] = e3d(S_est=cs.with_depth(runs[ch], z).S, S_true=S); row[mode + "_a"] = a
    else:
        row["main"] = row["hyb_agree"] = row["hyb_next"] = row["auto"]
    print(json.dumps({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()}), flush=True)
