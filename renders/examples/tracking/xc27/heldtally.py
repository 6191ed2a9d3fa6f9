"""Held-out totals (held.jsonl): per preset, main against XBKU (the chosen variant) and XKU (information only).
A reconstruction that stopped scores 0 with no accepted sighting (RULE.txt: main on hard 104)."""
import collections
import json

rows = [json.loads(line) for line in open("held.jsonl")]
by = collections.defaultdict(dict)
for r in rows:
    by[r["set"]][r["variant"]] = r
stopped = {"set": None, "visible": None, "accepted": 0, "within": 0, "over": 0, "score": 0}
for preset in ("default", "hard"):
    sets = sorted(s for s in by if s.startswith(preset))
    for v in ("main", "XBKU", "XKU"):
        got = [by[s].get(v, dict(stopped, visible=by[s]["XBKU"]["visible"])) for s in sets]
        vis = sum(g["visible"] for g in got)
        print(f"{preset:7s} {v:5s} total {sum(g['score'] for g in got):6d}  accepted "
              f"{100 * sum(g['accepted'] for g in got) / vis:.2f} %  over 3 px {sum(g['over'] for g in got):3d}  "
              + "  ".join(f"{s.split('_')[1]}:{g['score']}" for s, g in zip(sets, got)))
