import sys, collections, numpy as np
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
tot = collections.Counter()
for arg in sys.argv[1:]:
    s, path = arg.split("=")
    rec = Reconstruction.load(path); e = sighting_errors(load_truth(Dataset(f"/work/sets/{s}")), rec)
    V, R = e["virtual"], e["real"]
    vis = V["truly"] & R["truly"]
    un = vis & ~V["accepted"]
    gotV, gotR = V["got"] & (V["err"] <= 3), R["got"] & (R["err"] <= 3)
    everV = np.cumsum(V["got"], axis=0) > 0; neverV = ~V["got"].any(0)[None] & np.ones_like(un)
    c = collections.Counter()
    m = un & gotR & ~V["got"]
    c["mirror miss, never in clip"] += int((m & neverV).sum()); c["mirror miss, seen before"] += int((m & everV & ~neverV).sum())
    c["mirror miss, not yet"] += int((m & ~everV & ~neverV).sum())
    c["direct miss"] += int((un & gotV & ~R["got"]).sum())
    c["both lost"] += int((un & ~V["got"] & ~R["got"]).sum())
    c["both got right, not accepted"] += int((un & gotV & gotR).sum())
    c["a view wrong"] += int((un & ((V["got"] & ~gotV) | (R["got"] & ~gotR))).sum())
    c["total unaccepted pairs"] += int(un.sum()); c["visible pairs"] += int(vis.sum())
    tot.update(c)
print(dict(tot))
