import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
path, a, b = sys.argv[1:4]
name = path.rstrip("/").split("/")[-1]
ds=Dataset(path); tr=load_truth(ds); names=list(ds.marks)
E={}
for t in (a,b):
    r=Reconstruction.load(f"/work/reacq3/rec/{name}.{t}.npz"); E[t]=sighting_errors(tr,r)
for p,m in enumerate(names):
    rows=[]
    for view in ("virtual","real"):
        ss=[]
        for t in (a,b):
            e=E[t][view]; ok=e["ok"][:,p]; tru=e["truly"][:,p]; err=e["err"][:,p]
            ss.append("".join("x" if not tv else ("A" if o and er<=3 else ("W" if o else ".")) for o,er,tv in zip(ok,err,tru)))
        if ss[0]!=ss[1]:
            rows.append((view, ss))
    for view, ss in rows:
        print(f"{m:18s} {view:7s} {a:6s} {ss[0]}"); print(f"{'':18s} {'':7s} {b:6s} {ss[1]}")
