import pickle, glob, json, collections
import numpy as np
SETS = [1, 2, 3, 4, 5, 100, 101, 102, 103, 104]
VN = ("mirror", "direct")
D = {n: pickle.load(open(f"/work/diagdef/data_default_{n}.pkl", "rb")) for n in SETS}
out = []
def p(*a): out.append(" ".join(str(x) for x in a))

# Q1: losses per marker/view
pool = collections.Counter(); per = {}
for n, d in D.items():
    vis = d["vis"].transpose(1, 0, 2)  # (2,F,P1)
    lostm = vis & ~d["got"]; rej = vis & d["got"] & ~d["acc"][None]
    c = collections.Counter()
    for v in range(2):
        for k in range(d["P1"]):
            c[(d["names"][k], VN[v])] = (int(lostm[v, :, k].sum()), int(rej[v, :, k].sum()))
    per[n] = c
    for key, val in c.items():
        a = pool.get(key, (0, 0)); pool[key] = (a[0] + val[0], a[1] + val[1])
p("## Q1 pooled top marker/view (lost, rejected, total)")
for key, val in sorted(pool.items(), key=lambda kv: -sum(kv[1]))[:10]:
    p(key, val, sum(val))
tot = sum(sum(v) for v in pool.values()); p("pooled total visible-not-accepted", tot)
# per marker (both views) pooled
pm = collections.Counter()
for (m, v), val in pool.items(): pm[m] += sum(val)
p("per marker both views:", pm.most_common())
for n in SETS:
    top = sorted(per[n].items(), key=lambda kv: -sum(kv[1]))[:5]
    p(f"default_{n} top5:", [(k[0], k[1], v) for k, v in top], "total", sum(sum(v) for v in per[n].values()))
# marker never accepted / whole-sequence losses
p("## marks with >=100 losses in a set/view (likely never acquired / lost for good)")
for n in SETS:
    d = D[n]; vis = d["vis"].transpose(1, 0, 2)
    for v in range(2):
        for k in range(d["P1"]):
            nv = int((vis[v, :, k] & ~(d["acc"][:, k])).sum())
            if nv >= 60:
                lostf = np.flatnonzero(vis[v, :, k] & ~d["got"][v, :, k])
                accf = np.flatnonzero(vis[v, :, k] & d["acc"][:, k])
                p(f"  default_{n} {d['names'][k]} {VN[v]}: not accepted {nv}/{int(vis[v,:,k].sum())}, lost {len(lostf)}, first lost {lostf[:1]}, accepted frames {len(accf)} first {accf[:1]}")
json.dump({"pool": {f"{k[0]}|{k[1]}": v for k, v in pool.items()}}, open("/work/diagdef/q1.json", "w"))

# Q2: lost sightings: detector evidence
p("## Q2 lost sightings vs detector (whole-pixel peaks of dot_peaks)")
hdr = "set | lost | round peak<=1.5 (free) | round peak taken by other marker | elongated peak<=1.5 | peak 1.5-3 | no peak (<=3) | of no peak: resp>=thr (suppressed by nbr) | resp<thr | dvf<0.5 | other true mark <4px"
p(hdr)
agg = collections.Counter()
allrows = []
for n in SETS:
    rows = [r for r in D[n]["rows"] if r["kind"] == "lost"]
    c = collections.Counter()
    for r in rows:
        r["set"] = n; allrows.append(r)
        if r["dmin"] <= 1.5 and r["rnd"] >= 0.3:
            c["round_taken" if r["taken"] else "round_free"] += 1
        elif r["dmin"] <= 1.5:
            c["elong"] += 1
        elif r["dmin"] <= 3:
            c["near"] += 1
        else:
            c["none"] += 1
            c["none_strong" if r["resp"] >= r["thr"] else "none_weak"] += 1
        if r["dvf"] < 0.5: c["dvf"] += 1
        if r["other_d"] < 4: c["close"] += 1
    c["lost"] = len(rows); agg.update(c)
    p(f"default_{n} | {c['lost']} | {c['round_free']} | {c['round_taken']} | {c['elong']} | {c['near']} | {c['none']} | {c['none_strong']} | {c['none_weak']} | {c['dvf']} | {c['close']}")
c = agg
p(f"pooled | {c['lost']} | {c['round_free']} | {c['round_taken']} | {c['elong']} | {c['near']} | {c['none']} | {c['none_strong']} | {c['none_weak']} | {c['dvf']} | {c['close']}")
# by marker for no-peak vs present
bym = collections.defaultdict(collections.Counter)
for r in allrows:
    nm = D[r["set"]]["names"][r["p"]] + "|" + VN[r["v"]]
    cls = "present" if r["dmin"] <= 1.5 else ("near" if r["dmin"] <= 3 else "none")
    bym[nm][cls] += 1
p("lost by marker/view: present<=1.5 / near / none")
for k, v in sorted(bym.items(), key=lambda kv: -sum(kv[1].values()))[:14]:
    p("  ", k, dict(v))
# darkness of missed dots vs all visible dots
allvis = [r for n in SETS for r in D[n]["rows"] if r["kind"] == "all"]
rv = np.array([r["resp"] for r in allvis]); p("all visible dots response (every 5th frame): median %.3f p10 %.3f, share < thr %.3f" % (np.median(rv), np.percentile(rv, 10), np.mean([r['resp'] < r['thr'] for r in allvis])))
nop = [r for r in allrows if r["dmin"] > 3]
if nop:
    rr = np.array([r["resp"] for r in nop]); p("no-peak lost: response median %.3f p90 %.3f; dvf median %.2f; other-mark dist median %.1f px" % (np.nanmedian(rr), np.nanpercentile(rr, 90), np.median([r['dvf'] for r in nop]), np.median([r['other_d'] for r in nop])))
pres = [r for r in allrows if r["dmin"] <= 1.5]
if pres:
    p("present lost: roundness median %.2f, strength median %.3f, dvf median %.2f, other-mark dist median %.1f" % (np.nanmedian([r['rnd'] for r in pres]), np.nanmedian([r['strength'] for r in pres]), np.median([r['dvf'] for r in pres]), np.median([r['other_d'] for r in pres])))
    p("present lost, previous-frame status counts:", collections.Counter(r["status_prev"] for r in pres))
pickle.dump(allrows, open("/work/diagdef/lostrows.pkl", "wb"))

# Lost-run structure
p("## lost run lengths (per marker/view, visible & lost consecutive)")
lens = []
for n in SETS:
    d = D[n]; vis = d["vis"].transpose(1, 0, 2); L = vis & ~d["got"]
    for v in range(2):
        for k in range(d["P1"]):
            x = L[v, :, k].astype(int); run = 0
            for f in range(d["F"]):
                if x[f]: run += 1
                elif run: lens.append(run); run = 0
            if run: lens.append(run)
lens = np.array(lens)
p("runs", len(lens), "sightings", lens.sum(), "runs>=20 frames:", (lens >= 20).sum(), "covering", lens[lens >= 20].sum(), "; runs 1-2:", (lens <= 2).sum(), "covering", lens[lens <= 2].sum())

# Q3: accepted > 3 px
p("## Q3 accepted > 3 px")
tot = collections.Counter(); runs_all = []
for n in SETS:
    d = D[n]; c = collections.Counter()
    for v in range(2):
        T = d["tuv"][:, v]  # (F,P1,2)
        bad = d["vis"][:, v] & d["acc"] & (d["err"][v] > 3)
        for f, k in zip(*np.nonzero(bad)):
            o = np.linalg.norm(np.delete(T[f], k, 0) - d["uv"][v, f, k], axis=1)
            c["swap" if np.nanmin(o) <= 1.5 else ("near_other" if np.nanmin(o) <= 3 else "else")] += 1
        for k in range(d["P1"]):
            wr = d["got"][v, :, k] & (d["err"][v, :, k] > 3)  # wrong whether accepted or not
            f = 0
            while f < d["F"]:
                if wr[f]:
                    s = f
                    while f < d["F"] and wr[f]: f += 1
                    acc_in = int((bad[s:f, k]).sum())
                    if acc_in:
                        onm = None
                        o = np.linalg.norm(np.delete(T[s], k, 0) - d["uv"][v, s, k], axis=1)
                        onames = [x for i, x in enumerate(d["names"]) if i != k]
                        runs_all.append((n, d["names"][k], VN[v], s, f - 1, acc_in, onames[int(np.nanargmin(o))], round(float(np.nanmin(o)), 1), round(float(d["err"][v, s, k]), 1)))
                else:
                    f += 1
    tot.update(c); p(f"default_{n}", dict(c))
p("pooled", dict(tot))
p("wrong runs (set, marker, view, first, last, accepted>3px in run, nearest other true mark at start, its dist, err at start):")
for x in sorted(runs_all, key=lambda x: -x[5]): p("  ", x)

# Q4 set features
p("## Q4 per-set features")
from scipy.spatial.transform import Rotation as R
p("set | accepted% | head rot range deg | head trans range mm | mouth open max mm | mouth open p90 | min dist between true dots px (p5) | dot resp median | " + " | ".join(D[1]["manifest_subject"].keys()))
acc_share = {1: 96.5, 100: 93.2, 101: 91.3, 102: 85.2, 103: 81.2, 104: 86.4, 2: 62.7, 3: 97.2, 4: 87.1, 5: 97.7}
for n in sorted(SETS, key=lambda n: acc_share[n]):
    d = D[n]; pose = d["pose"]
    rot = R.from_matrix(pose[:, :3, :3]); rel = (rot * rot[0].inv()).magnitude() * 180 / np.pi
    tr = np.linalg.norm(pose[:, :3, 3] - pose[0, :3, 3], axis=1)
    nm = d["names"]; mm = d["marks_model"]
    op = np.linalg.norm(mm[:, nm.index("upper_mid")] - mm[:, nm.index("lower_mid")], axis=1)
    # closest pair of visible true projections per frame/view
    mins = []
    for f in range(0, d["F"], 5):
        for v in range(2):
            T = d["tuv"][f, v][d["vis"][f, v]]
            if len(T) > 1:
                dd = np.linalg.norm(T[:, None] - T[None], axis=2); dd[np.diag_indices(len(T))] = np.inf; mins.append(dd.min())
    rv = np.median([r["resp"] for r in d["rows"] if r["kind"] == "all"])
    sh = d["manifest_subject"]
    p(f"default_{n} | {acc_share[n]} | {rel.max():.1f} | {tr.max():.1f} | {op.max():.1f} | {np.percentile(op,90):.1f} | {np.percentile(mins,5):.1f} | {rv:.3f} | " + " | ".join(f"{x:.2f}" for x in sh.values()))
open("/work/diagdef/summary.txt", "w").write("\n".join(out))
print("\n".join(out))
