import json, collections
rows = [json.loads(l) for l in open("/work/b37/hoB.jsonl")]
N = {r["set"]: r for r in rows if r["variant"] == "B"}; M = {r["set"]: r for r in rows if r["variant"] == "main"}
tot = collections.Counter()
for s in sorted(N, key=lambda x: (x[:4], int(x[4:]) if x[4:].isdigit() else 0)):
    n = N[s]; m = M.get(s)
    ms = m["score"] if m else (n["score"] if not n.get("shared") else None)
    pre = s.rstrip("0123456789")
    tot[(pre, "B")] += n["score"]; tot[(pre, "main")] += ms if ms is not None else 0
    print(s, "B", n["score"], "main", ms, "" if m else "(same: no span)" if not n.get("shared") else "MISSING", "diff", None if ms is None else n["score"] - ms, "spans", len(n.get("shared") or []))
print(dict(tot))
