import pickle, numpy as np, collections
SETS = [1, 2, 3, 4, 5, 100, 101, 102, 103, 104]
sp_on, sp_all, op_on, op_all, opq = [], [], [], [], []
runs = collections.Counter()
for n in SETS:
    d = pickle.load(open(f"/work/diagdef/data_default_{n}.pkl", "rb"))
    nm = d["names"]; mm = d["marks_model"]
    op = np.linalg.norm(mm[:, nm.index("upper_mid")] - mm[:, nm.index("lower_mid")], axis=1)
    rank = op.argsort().argsort() / (len(op) - 1)
    for v in range(2):
        T = d["tuv"][:, v]; sp = np.r_[np.zeros((1, d["P1"])), np.linalg.norm(np.diff(T, axis=0), axis=2)]
        na = d["vis"][:, v] & ~d["acc"]
        for p in range(d["P1"] - 1):
            ok = d["got"][v, :, p] & (d["err"][v, :, p] <= 1.5)
            if not ok.any(): continue
            f0 = np.argmax(ok)
            for f in range(f0 + 1, d["F"]):
                sp_all.append(sp[f, p]); op_all.append(op[f])
                if na[f, p] and not na[f-1, p]:
                    sp_on.append(max(sp[f, p], sp[f-1, p])); op_on.append(op[f]); opq.append(rank[f])
print("onsets of loss/reject runs after a correct start:", len(sp_on))
print("true dot speed px/frame at onset: median %.2f p90 %.2f | all frames median %.2f p90 %.2f" % (np.median(sp_on), np.percentile(sp_on, 90), np.median(sp_all), np.percentile(sp_all, 90)))
print("mouth opening mm at onset: median %.1f | all frames median %.1f ; onsets in the set's top-quartile opening frames: %.0f%%" % (np.median(op_on), np.median(op_all), 100*np.mean(np.array(opq) >= 0.75)))
