"""Per set, the candidate's score against main's (main not run where the candidate found no span: equal by
construction). usage: tally.py ROWS.jsonl CANDIDATE  (ho_N.jsonl N, ho_B.jsonl B)"""
import sys, json, collections
rows = [json.loads(l) for l in open(sys.argv[1])]; tag = sys.argv[2]
C = {r["set"]: r for r in rows if r["variant"] == tag}; M = {r["set"]: r for r in rows if r["variant"] == "main"}
tot = collections.Counter()
for s in sorted(C, key=lambda x: (x.rstrip("0123456789"), int(x.lstrip("abcdefghijklmnopqrstuvwxyz")))):
    c, m = C[s], M.get(s)
    ms = m["score"] if m else (c["score"] if not c.get("shared") else None)
    pre = s.rstrip("0123456789")
    tot[(pre, tag)] += c["score"]; tot[(pre, "main")] += ms or 0
    print(s, tag, c["score"], "main", ms, "" if m else "(same: no span)" if not c.get("shared") else "MISSING",
          "diff", None if ms is None else c["score"] - ms, "spans", len(c.get("shared") or []))
print(dict(tot))
