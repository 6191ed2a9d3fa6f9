"""Development totals per variant over the sets every eligible variant has (dev.jsonl, devK.jsonl; devA.jsonl is
the stopped XA/XBA run, listed apart). usage: tally.py"""
import collections
import json

rows = [json.loads(line) for f in ("dev.jsonl", "devK.jsonl") for line in open(f)]
by = collections.defaultdict(dict)
for r in rows:
    by[r["set"]][r["variant"]] = r
variants = ["main", "X", "XU", "XB", "XBU", "XKU", "XBKU"]
complete = [s for s, d in by.items() if all(v in d for v in variants)]
print(f"{len(complete)} sets with every variant")
for v in variants:
    tot = sum(by[s][v]["score"] for s in complete)
    down = [f"{s} {by[s][v]['score'] - by[s]['main']['score']:+d}" for s in complete
            if by[s][v]["score"] - by[s]["main"]["score"] < -50]
    acc = sum(by[s][v]["accepted"] for s in complete) / sum(by[s][v]["visible"] for s in complete)
    over = sum(by[s][v]["over"] for s in complete)
    print(f"{v:5s} total {tot:6d} ({tot - sum(by[s]['main']['score'] for s in complete):+5d}) accepted {100 * acc:.2f} % "
          f"over {over:4d}; down > 50: {', '.join(down) or 'none'}")
for preset in ("hard", "default"):
    sets = [s for s in complete if s.startswith(preset)]
    print(preset, {v: sum(by[s][v]["score"] for s in sets) for v in variants})
