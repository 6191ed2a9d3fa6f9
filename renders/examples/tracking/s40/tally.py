"""Per-set score against main (W) for each variant in the given JSON-lines files: tally.py FILE... (rows from
run.py; a set's W row may sit in another file)."""
import sys, json, collections
rows = collections.defaultdict(dict)
for path in sys.argv[1:]:
    for line in open(path):
        r = json.loads(line)
        rows[r["set"]][r["variant"]] = r
variants = sorted({v for s in rows.values() for v in s if v != "W"})
print("| set | main: accepted / over 3 px / score | " + " | ".join(variants) + " |")
print("|---|---|" + "---|" * len(variants))
tot = collections.Counter()
for name in sorted(rows, key=lambda s: (s.rstrip("0123456789"), int(s.lstrip("a-z") or 0) if False else s)):
    w = rows[name].get("W")
    if w is None:
        continue
    cells = []
    for v in variants:
        r = rows[name].get(v)
        if r is None:
            cells.append("")
            continue
        d = r["score"] - w["score"]
        tot[v] += d
        cells.append(f"{d:+d} ({r['accepted']} / {r['over']})")
    print(f"| {name} | {w['accepted']} / {w['over']} / {w['score']} | " + " | ".join(cells) + " |")
print("| total | | " + " | ".join(f"{tot[v]:+d}" for v in variants) + " |")
