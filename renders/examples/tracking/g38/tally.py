"""g38 tally: per set and total score of each variant, from jsonl rows; the differences against main.
usage: tally.py ROWS.jsonl..."""
import json, sys
rows = [json.loads(l) for f in sys.argv[1:] for l in open(f) if l.strip()]
sets = list(dict.fromkeys(r["set"] for r in rows))
tags = list(dict.fromkeys(r["variant"] for r in rows))
by = {(r["set"], r["variant"]): r for r in rows}
print("| set | " + " | ".join(tags) + " |")
print("|---|" + "---|" * len(tags))
tot = {t: 0 for t in tags}
for s in sets:
    m = by.get((s, "main"))
    cells = []
    for t in tags:
        r = by.get((s, t))
        if r is None:
            cells.append("—"); continue
        tot[t] += r["score"]
        if "stopped" in r:
            cells.append("stopped (0)")
        elif t == "main":
            cells.append(f"{r['score']} ({r['share']} %, {r['over']})")
        else:
            cells.append(f"{r['score'] - m['score']:+d} ({r['share']} %, {r['over']}; filled {r['gap_fill']['filled']})")
    print(f"| {s} | " + " | ".join(cells) + " |")
print("| total | " + " | ".join(str(tot[t]) for t in tags) + " |")
for t in tags:
    acc = sum(by[(s, t)].get("accepted", 0) for s in sets if (s, t) in by)
    vis = sum(by[(s, t)].get("visible", 0) for s in sets if (s, t) in by)
    over = sum(by[(s, t)].get("over", 0) for s in sets if (s, t) in by)
    print(f"{t}: accepted {acc}/{vis} = {100*acc/max(vis,1):.2f} %, over 3 px {over}")
