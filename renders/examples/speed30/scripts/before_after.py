import json, tempfile
from pathlib import Path
from lipgen.bench import generate_cpu as g
here = Path("/work/wt/speed30")
with tempfile.TemporaryDirectory() as tmp:
    base = g.base_tree(Path(tmp) / "base")
    before = g.base_tree(Path(tmp) / "before", "8f8aa24")
    hard = g.RENDER_ENV | {"LIPGEN_BENCH_PRESET": "hard", "LIPGEN_BENCH_PHYSICS": "layer"}
    envs = {"base_one_thread": g.RENDER_ENV | g.ONE_THREAD_ENV, "layer_before": hard, "layer_now": hard}
    out = g.generate_cpu({"base_one_thread": base, "layer_before": before, "layer_now": here}, "base_one_thread",
                         1, 6, 36, 3, envs=envs)
print(json.dumps(out))
