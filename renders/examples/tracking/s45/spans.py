"""Each cross-check dispute span on spent sets (truth read): which run was right, the layout's 3-D figures and
verdict, and in how many frames each run had a pair. spans.py DUMP SET...  (DUMP: dump.py's OUT)"""
import os, sys, collections, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from dumped import dumped, spans
from lipgen.recon.crosscheck import layout_residuals

frames = collections.Counter()
for name, cap, tuv in dumped(sys.argv[1], sys.argv[2:]):
    a, b, disputed, cams, rest, cov, verdict = cap
    err = [np.stack([np.linalg.norm(run[v].uv - tuv[v], axis=-1) for v in range(2)]) for run in (a, b)]
    ra, rb, _, both_a, both_b = layout_residuals(a, b, disputed, cams, rest, cov)
    for m in range(disputed.shape[1]):
        for s, e in spans(disputed, m):
            worst = [np.nanmax(x[:, s:e, m]) if np.isfinite(x[:, s:e, m]).any() else np.nan for x in err]
            right = ["A" if w <= 3 else "" for w in worst[:1]] + ["B" if w <= 3 else "" for w in worst[1:]]
            who = "".join(right) or "neither"
            ok = np.isfinite(ra[s:e, m]) & np.isfinite(rb[s:e, m])
            a2, b2 = int(both_a[s:e, m].sum()), int(both_b[s:e, m].sum())
            kind = ("judged" if ok.any() else "only A has pairs" if a2 and not b2 else
                    "only B has pairs" if b2 and not a2 else "neither has pairs" if not (a2 or b2) else "mixed")
            frames[(kind, who, int(verdict[s, m]))] += e - s
            fig = f"ra {ra[s:e, m][ok].mean():5.2f} rb {rb[s:e, m][ok].mean():5.2f}" if ok.any() else "unjudged"
            print(f"{name} {m:2d} frames {s}-{e - 1} right {who:7s} worst A {worst[0]:5.1f} B {worst[1]:5.1f} px "
                  f"{fig} verdict {verdict[s, m]} pairs A {a2} B {b2} of {e - s}")
print("\nframes by (span, right run, verdict; 1 = the first run's stands, 2 = the second's, 0 = undecided):")
for k in sorted(frames):
    print(" ", k, frames[k])
