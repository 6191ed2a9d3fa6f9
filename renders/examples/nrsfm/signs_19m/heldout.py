"""Held-out scoring for nrsfm19m: main's k='auto' answer (cached) against the branch's consensus on the
same runs. Usage: heldout.py CACHE_DIR > rows.jsonl"""
import glob, importlib.util, json, pickle, sys
import numpy as np
from lipgen.nrsfm.consensus import consensus_reconstruction as main_consensus
from lipgen.nrsfm.kchoice import shrink_depth
from lipgen.nrsfm.metrics import e3d

spec = importlib.util.spec_from_file_location("branch_consensus", "/work/wt/signs/lipgen/nrsfm/consensus.py")
branch = importlib.util.module_from_spec(spec); spec.loader.exec_module(branch)

for f in sorted(glob.glob(sys.argv[1] + "/*.pkl")):
    d = pickle.load(open(f, "rb"))
    rec, runs, ch, S = d["rec"], d["runs"], d["chosen"], d["S"]
    row = dict(name=d["name"], flat=e3d(S_est=shrink_depth(rec, 0.0).S, S_true=S), main=e3d(S_est=rec.S, S_true=S))
    row["cand"], row["signs"] = row["main"], "unchanged path"
    if runs is not None and rec.depth_supported and rec.info.get("shapes") != "rank-K fit":
        again = main_consensus(runs, ch)
        assert np.allclose(again.S, rec.S, rtol=0, atol=1e-12 * np.abs(rec.S).max()), d["name"]            # the cached answer is main's consensus
        c = branch.consensus_reconstruction(runs, ch)
        row["cand"], row["signs"] = e3d(S_est=c.S, S_true=S), c.info["depth_consensus"]["signs"]
    print(json.dumps({k: (round(v, 5) if isinstance(v, float) else v) for k, v in row.items()}), flush=True)
