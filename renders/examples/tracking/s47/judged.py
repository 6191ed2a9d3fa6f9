"""What the continuity judge changes on spent sets (truth read): frames whose verdict differs from main's
(layout, then pairs) once continuity goes first, by which run was right over the span.
judged.py DUMP SET...  (DUMP: s45/dump.py's OUT)"""
import os, sys, collections
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "s45"))
from dumped import dumped, spans, right_run
from lipgen.recon.crosscheck import arbitrate

moved = collections.Counter()
for name, (a, b, disputed, cams, rest, cov, _), tuv in dumped(sys.argv[1], sys.argv[2:]):
    main = arbitrate(a, b, disputed, cams, rest, cov, pairs=True)
    new = arbitrate(a, b, disputed, cams, rest, cov, pairs=True, continuity=True)
    for m in range(disputed.shape[1]):
        for s, e in spans(disputed, m):
            changed = (main[s:e, m] != new[s:e, m]).sum()
            if changed:
                who = right_run(a, b, tuv, s, e, m)
                print(f"{name} marker {m:2d} frames {s}-{e - 1}: main {main[s:e, m].tolist()} -> "
                      f"{new[s, m]}; right: {who}")
                moved[(int(new[s, m]), who)] += int(changed)
print("\nframes changed, by (new verdict: 1 first run, 2 second; right run over the span):")
for k in sorted(moved):
    print(" ", k, moved[k])
