"""Verdict of chol32's RULE2: per-case means over three draws, D and its standard error."""
import json, sys, numpy as np
def load(p):
    out = {}
    for r in map(json.loads, open(p)):
        out.setdefault((r["name"], r["kind"]), []).append(r)
    return out
m, b = load(sys.argv[1]), load(sys.argv[2])
cases = sorted(k for k in m if k[1] != "none")
print("| body | kind | main e3D (3 draws) | branch e3D (3 draws) | main CPU s (x, first) | branch CPU s (x, first) | main K / supported | branch K / supported |")
print("|---|---|---|---|---|---|---|---|")
dm, db, var, tm, tb, om, ob = [], [], 0.0, 0.0, 0.0, 0, 0
for k in cases:
    em = [r["e"] for r in sorted(m[k], key=lambda r: r["draw"])]; eb = [r["e"] for r in sorted(b[k], key=lambda r: r["draw"])]
    assert len(em) == len(eb) == 3, k
    cm = m[(k[0], "none")][0]["cpu"]; cb = b[(k[0], "none")][0]["cpu"]
    fm = m[k][0]["cpu"]; fb = b[k][0]["cpu"]
    tm += sum(r["cpu"] for r in m[k]); tb += sum(r["cpu"] for r in b[k])
    om += fm / cm > 5; ob += fb / cb > 5
    dm.append(np.mean(em)); db.append(np.mean(eb)); var += np.var(em, ddof=1) + np.var(eb, ddof=1)
    ks = lambda rs: ",".join(f"{r['k']}{'' if r['supported'] else 'F'}" for r in sorted(rs, key=lambda r: r["draw"]))
    print(f"| {k[0]} | {k[1]} | {' / '.join(map(str, em))} | {' / '.join(map(str, eb))} | {fm} ({fm/cm:.2f}) | {fb} ({fb/cb:.2f}) | {ks(m[k])} | {ks(b[k])} |")
n = len(cases); D = np.mean(db) - np.mean(dm); SE = np.sqrt(var / 3 / n**2)
print(f"\ncases {n}; mean e3D main {np.mean(dm):.4f} branch {np.mean(db):.4f}; D {D:+.4f}, SE {SE:.4f}, bound {max(0.002, 2*SE):.4f} "
      f"(a: {'pass' if D <= max(0.002, 2*SE) else 'FAIL'}); total CPU main {tm:.1f} branch {tb:.1f} (b: {'pass' if tb < tm else 'FAIL'}); "
      f"over 5x (first run): main {om}, branch {ob}")
print(f"chaos: mean within-case std main {np.mean([np.std([r['e'] for r in m[k]], ddof=1) for k in cases]):.4f}, branch {np.mean([np.std([r['e'] for r in b[k]], ddof=1) for k in cases]):.4f}; "
      f"cases whose 3 runs differ: main {sum(len({r['e'] for r in m[k]}) > 1 for k in cases)}, branch {sum(len({r['e'] for r in b[k]}) > 1 for k in cases)}")
