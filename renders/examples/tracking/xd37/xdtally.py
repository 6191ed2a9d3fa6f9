import json, collections, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
by = collections.defaultdict(dict)
for r in rows: by[r["set"]][r["variant"]] = r
tot = collections.Counter(); down = []
for s, v in by.items():
    if "base" in v and "XD" in v:
        pre = s.rstrip("0123456789"); d = v["XD"]["score"] - v["base"]["score"]
        tot[(pre, "base")] += v["base"]["score"]; tot[(pre, "XD")] += v["XD"]["score"]
        for k in ("accepted", "over", "visible"):
            tot[(pre, "base", k)] += v["base"].get(k, 0); tot[(pre, "XD", k)] += v["XD"].get(k, 0)
        if d < -50: down.append((s, d))
        print(s, "base", v["base"]["score"], "XD", v["XD"]["score"], "diff", d)
print(dict(tot)); print("down > 50:", down)
