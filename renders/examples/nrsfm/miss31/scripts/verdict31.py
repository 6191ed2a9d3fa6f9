import json, sys
main = {(r['name'], r['kind']): r for r in map(json.loads, open(sys.argv[1]))}
br = {(r['name'], r['kind']): r for r in map(json.loads, open(sys.argv[2]))}
comp = {k[0]: r['cpu'] for k, r in br.items() if k[1] == 'none'}
tm = tb = em = eb = 0; n = 0; flips = 0; over_m = over_b = 0
print("| body | kind | complete CPU s | main CPU s (x) | branch CPU s (x) | main e3D / angle / supported | branch e3D / angle / supported |")
print("|---|---|---|---|---|---|---|")
for k in sorted(main):
    a, b = main[k], br[k]; c = comp[k[0]]
    tm += a['cpu']; tb += b['cpu']; em += a['e']; eb += b['e']; n += 1
    flips += a['supported'] != b['supported']; over_m += a['cpu'] / c > 5; over_b += b['cpu'] / c > 5
    print(f"| {k[0]} | {k[1]} | {c} | {a['cpu']} ({a['cpu']/c:.2f}) | {b['cpu']} ({b['cpu']/c:.2f}) | {a['e']} / {a['angle']} / {a['supported']} | {b['e']} / {b['angle']} / {b['supported']} |")
print(f"\ncases {n}; mean e3D main {em/n:.4f} branch {eb/n:.4f} (a: {'pass' if eb/n <= em/n + 0.002 else 'FAIL'}); "
      f"total CPU main {tm:.1f} branch {tb:.1f} (b: {'pass' if tb < tm else 'FAIL'}); support decisions changed {flips}; "
      f"over 5x: main {over_m}, branch {over_b}")
