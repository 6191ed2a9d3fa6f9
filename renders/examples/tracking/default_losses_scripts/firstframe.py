import pickle, numpy as np, collections
SETS = [1, 2, 3, 4, 5, 100, 101, 102, 103, 104]; VN = ("mirror", "direct")
print("set | frame-0 visible marks wrong(>3px) or lost (list) | visible-not-accepted sightings: before the track's first correct sighting / after | of which marker/view never correct")
tot = collections.Counter()
for n in SETS:
    d = pickle.load(open(f"/work/diagdef/data_default_{n}.pkl", "rb"))
    bad0 = []; before = after = never = 0
    for v in range(2):
        vis = d["vis"][:, v]; acc = d["acc"]; err = d["err"][v]; got = d["got"][v]
        for p in range(d["P1"]):
            if vis[0, p] and (not got[0, p] or err[0, p] > 3):
                bad0.append(f"{d['names'][p]}/{VN[v]}:{'lost' if not got[0,p] else f'{err[0,p]:.0f}px'}")
            ok = got[:, p] & (err[:, p] <= 1.5)
            first = np.argmax(ok) if ok.any() else d["F"]
            na = vis[:, p] & ~acc[:, p]
            before += int(na[:first].sum()); after += int(na[first:].sum())
            if not ok.any(): never += int(na.sum())
    tot.update(dict(before=before, after=after, never=never))
    print(f"default_{n} | {len(bad0)}: {', '.join(bad0)} | {before} / {after} | {never}")
print(dict(tot))
