import json, sys, numpy as np
for f in sys.argv[1:]:
    d = json.load(open(f))
    ps = d['per_seed']
    print("==", f, len(ps), "seeds")
    for split in ("utterance", "subject"):
        for est in ("modes", "full", "combined", "physics_force"):
            v = np.array([p[split]["xyz (8 points)"][est]["truth_relative"] for p in ps])
            a = np.array([p[split]["xyz (8 points)"][est]["truth"] for p in ps])
            print(f"  {split:9s} {est:14s} xyz rel mean {v.mean():.3f} median {np.median(v):.3f} max {v.max():.2f} (>1: {np.sum(v>1)}) | mm2 mean {a.mean():.2f}")
    for part in ("train", "utterance", "subject"):
        e = np.array([p["marker_error_mm"][part]["rms"] for p in ps])
        print(f"  marker disp err {part:9s} rms mean {e.mean():.2f} median {np.median(e):.2f} max {e.max():.2f}")
    print("  separated", {s: {r: sum(v.values()) for r, v in d['separated'][s].items()} for s in d['separated']})
    print("  order x-y/y-z", json.dumps(d['order_xy_over_yz'])[:300])
