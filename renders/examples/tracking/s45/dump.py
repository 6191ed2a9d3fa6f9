"""The cross-check judge's inputs on spent sets, from main's defaults before s45 (cross_check_pairs off) with the
tracking memoised (w39/cached.py):
dump.py MEMO OUT SET...  writes OUT/SET.arb.pkl = (first, second, disputed, cameras, rest, covariance, verdict)."""
import os, sys, pickle
memo, out = sys.argv[1], sys.argv[2]
os.environ["MEMO_DIR"] = memo
sys.path[:0] = [os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "w39")]
import cached
import lipgen.recon.pipeline as pl
from lipgen.recon.settings import ReconstructSettings
judge, caught = pl.arbitrate, {}


def spy(a, b, disputed, cams, rest, cov=None, **kw):
    verdict = judge(a, b, disputed, cams, rest, cov, **kw)
    caught["args"] = (a, b, disputed, cams, rest, cov, verdict)
    return verdict


pl.arbitrate = spy
for name in sys.argv[3:]:
    cached.use(name)
    caught.clear()
    pl.reconstruct_dataset(f"/work/sets/{name}", settings=ReconstructSettings(cross_check_pairs=False))
    with open(f"{out}/{name}.arb.pkl", "wb") as fh:
        pickle.dump(caught.get("args"), fh)
