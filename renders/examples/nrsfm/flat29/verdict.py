"""flat29: the rule's four criteria from rough.py's rows (main = the library's answer, R5 = the consensus of the Ks
within 5 x the least roughness, from the same runs; a case whose depth the support test refused is flat in both).
usage: verdict.py LIPS.jsonl BODIES.jsonl CHECKS.jsonl"""
import json
import sys

import numpy as np


def rows(path):
    return [json.loads(line) for line in open(path) if line.strip()]


def main_of(r):
    return r["auto"]


def r5_of(r):
    return r.get("R5", r["auto"])


def worse(rs, of):
    return [r["name"] for r in rs if of(r) > r["flat"] * (1 + 1e-9)]


lips, bodies, checks = (rows(p) for p in sys.argv[1:4])
for name, rs in (("lip views", lips), ("bodies", bodies)):
    print(f"{name} (n {len(rs)}): flat {np.mean([r['flat'] for r in rs]):.4f}; "
          f"main {np.mean([main_of(r) for r in rs]):.4f}, worse than flat {len(worse(rs, main_of))} {worse(rs, main_of)}; "
          f"R5 {np.mean([r5_of(r) for r in rs]):.4f}, worse than flat {len(worse(rs, r5_of))} {worse(rs, r5_of)}")
a = len(worse(lips + bodies, r5_of)) < len(worse(lips + bodies, main_of))
b = np.mean([r5_of(r) for r in lips]) < np.mean([r["flat"] for r in lips])
c = np.mean([r5_of(r) for r in bodies]) <= np.mean([main_of(r) for r in bodies]) + 0.005
moved = [(r["name"], main_of(r), r5_of(r)) for r in checks if r5_of(r) > main_of(r) + 1e-3]
d = not moved
print("checks (drink, jaws, CMU):", [(r["name"], main_of(r), r5_of(r)) for r in checks])
print(f"(a) fewer worse than flat: {a}; (b) lips below flat's mean: {b}; (c) bodies within +0.005: {c}; "
      f"(d) no check up by > 1e-3: {d} {moved}")
print("PASS" if a and b and c and d else "FAIL")
