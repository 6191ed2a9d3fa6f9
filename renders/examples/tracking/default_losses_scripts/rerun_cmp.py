import pickle, sys, collections, numpy as np
n = sys.argv[1]
R = pickle.load(open(f"/work/diagdef/rerun_{n}.pkl", "rb"))
d = pickle.load(open(f"/work/diagdef/data_default_{n}.pkl", "rb"))
print("final status identical to stored recon:", np.array_equal(R["status"], d["status"]), "uv close:", np.allclose(np.nan_to_num(R["uv"]), np.nan_to_num(d["uv"])))
F, P1 = d["F"], d["P1"]
st = np.full((2, F, P1), -1); uvs = np.full((2, F, P1, 2), np.nan); cnt = [0, 0]
for k, uv, s, a in R["rec"]:
    st[k, cnt[k]] = s; uvs[k, cnt[k]] = uv; cnt[k] += 1
print("steps per tracker", cnt)
# tracker k order: assume k=0 virtual, 1 real (check by comparing)
for k in range(2):
    print("tracker", k, "agrees with view 0:", np.mean(st[k] == d["status"][0]), "view 1:", np.mean(st[k] == d["status"][1]))
rows = {(r["f"], r["v"], r["p"]): r for r in d["rows"] if r["kind"] == "lost"}
c = collections.Counter()
for (f, v, p), r in rows.items():
    own = st[v, f, p]
    det = "dot present" if r["dmin"] <= 1.5 else ("no dot" if r["dmin"] > 3 else "near")
    if own == 3: w = "tracker lost it"
    else:
        e = np.linalg.norm(uvs[v, f, p] - d["tuv"][f, v, p])
        w = "tracker had it (<=1.5px), withdrawn by checks" if e <= 1.5 else "tracker had a wrong dot, withdrawn"
    c[(det, w)] += 1
for k, v in sorted(c.items()): print(k, v)
P = {(r["f"], r["v"], r["p"]): r for r in pickle.load(open("/work/diagdef/pred.pkl", "rb")) if r["set"] == int(n)}
def cls(r):
    if not np.isfinite(r["dpred"]): return "never seen in this view yet"
    if r["dpred"] > r["reach"]: return "carried prediction out of reach"
    if r["rivals"] > 0: return "nearer rival dot"
    return "true dot nearest to prediction"
c2 = collections.Counter(); bym = collections.Counter()
for (f, v, p), r in rows.items():
    if r["dmin"] <= 1.5 and st[v, f, p] == 3:
        c2[cls(P[(f, v, p)])] += 1; bym[(d["names"][p], ("mirror", "direct")[v])] += 1
print("tracker-lost with dot present, by replayed prediction:", dict(c2))
print("  by marker:", bym.most_common(6))
