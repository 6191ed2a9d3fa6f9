import sys, json, logging
logging.disable(logging.WARNING)
sys.path.insert(0, '/work/wt/rest')
import lipgen; assert lipgen.__file__.startswith('/work/wt/rest')
from pathlib import Path
from lipgen.experiments.table51_pipeline import PipelineSettings, run_pipeline, write_pipeline_report
work, out, rest = sys.argv[1], Path(sys.argv[2]), sys.argv[3]
seeds = tuple(int(s) for s in sys.argv[4:])
res = run_pipeline(PipelineSettings(seeds=seeds, rest=rest), work=work, progress=False)
out.mkdir(parents=True, exist_ok=True)
write_pipeline_report(res, out)
