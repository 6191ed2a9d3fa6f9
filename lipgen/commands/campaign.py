"""``lipgen campaign``: many datasets through the stages on Ray, and one report over them."""

from __future__ import annotations

import argparse
import sys

_EPILOG = """\
PLAN.toml (every key is checked before anything runs):

  [campaign]
  stages = ["generate", "reconstruct", "train", "evaluate", "nrsfm"]   # default: all
  chunk_frames = 16          # frames per generate task
  retries = 2                # re-runs of a task whose worker died
  [base]                     # generate settings of every item (lipgen.dataset.GenerateSettings fields)
  frames = 60
  size = "640x480"
  [grid]                     # every combination of these lists
  seed = [0, 1, 2, 3, 4]
  noise = [0.5, 1.0, 2.0]
  [[items]]                  # crossed with each of these (optional)
  script = "AA:0.3 EE OO M F"
  [train]                    # modes, test_frames
  [reconstruct]              # normalisation, mesh
  [nrsfm]                    # view, k, method

DIR/campaign.json is the index (each item's settings, status, timings, errors, versions);
DIR/items/NNNN/ hold each item's dataset (byte-identical to lipgen generate with the same
settings), recon.npz, model.npz, report/ and nrsfm.json. A folder holding anything else is
refused, and so is a second campaign into the same folder. Without --address an embedded Ray
runs on this machine's cores; with one, the campaign runs on that cluster (every worker must
see DIR at the same path). DIR/campaign.parquet is the index as a table (pyarrow).

--out may also be a store URL (fsspec): s3://bucket/x (s3fs), gs://bucket/x (gcsfs),
file:///path/x. Tasks stage on their worker ($LIPGEN_STAGING, default the temp folder) and
upload each file whole, a frame's truth last; --resume continues at the missing frames.

examples:
  lipgen campaign plan.toml --out runs/noise
  lipgen campaign plan.toml --out runs/noise --resume
  lipgen campaign plan.toml --out /shared/runs/noise --address head-node:6379
  lipgen campaign plan.toml --out s3://my-bucket/runs/noise --address auto
  lipgen campaign report runs/noise
"""


def add_parser(sub) -> None:
    p = sub.add_parser("campaign", help="run many datasets through the stages on Ray; one aggregated report",
                       description="Run a plan of many synthetic datasets (a grid of generate settings) "
                       "through generate -> reconstruct -> train -> evaluate and NRSfM as Ray tasks, or "
                       "(lipgen campaign report DIR) write one report over a campaign's items.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("plan", metavar="PLAN.toml|report", help="the plan file, or 'report' to report on DIR")
    p.add_argument("dir", nargs="?", metavar="DIR", help="with 'report': the campaign folder")
    p.add_argument("--out", help="campaign folder or store URL (s3://, gs://, file://): new or empty; "
                   "or this plan's campaign with --resume")
    p.add_argument("--address", help="a running Ray cluster: HOST:PORT, ray://HOST:PORT or auto "
                   "(default: an embedded local Ray)")
    p.add_argument("--resume", action="store_true", help="continue a stopped campaign of the same plan")
    p.add_argument("--workers", type=int, default=None, help="CPUs of the embedded Ray (default: all cores)")
    p.add_argument("--executor", choices=("ray", "local"), default="ray",
                   help="ray (default) or local processes, without Ray")
    p.add_argument("--dashboard", action="store_true", help="start Ray's dashboard (embedded Ray)")
    p.add_argument("--report-out", help="with 'report': report folder (default DIR/report)")
    p.add_argument("--force", action="store_true",
                   help="with 'report' and --report-out: replace the report files there")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from lipgen.campaign.remote import is_uri
    from lipgen.commands._output import check_folder_output

    if args.plan == "report":
        from lipgen.campaign.aggregate import write_campaign_report

        if not args.dir:
            raise ValueError("lipgen campaign report needs the campaign folder: lipgen campaign report DIR")
        if args.report_out is not None and not is_uri(args.report_out):  # DIR/report is the campaign's own
            check_folder_output(args.report_out, args.force, ("report.md", "report.json"), "--report-out")
        path = write_campaign_report(args.dir, args.report_out)
        sys.stdout.write(f"report: {path}\n")
        return 0
    from lipgen.campaign import load_plan, run_campaign

    if args.dir:
        raise ValueError(f"unexpected argument {args.dir!r}; the campaign folder is given with --out")
    if not args.out:
        raise ValueError("--out DIR is required: the campaign folder")
    if not is_uri(args.out):
        check_folder_output(args.out, True, (), "--out")  # a new folder's parent exists: none made on the way
    plan = load_plan(args.plan)
    index = run_campaign(plan, args.out, executor=args.executor, address=args.address, workers=args.workers,
                         resume=args.resume, progress=not args.no_progress, dashboard=args.dashboard)
    items = index["items"]
    done = sum(e["status"] == "done" for e in items)
    failed = [e["name"] for e in items if e["status"] == "failed"]
    sys.stdout.write(f"{done}/{len(items)} items done" + (f", failed: {', '.join(failed)}" if failed else "")
                     + f"; index {args.out}/campaign.json; lipgen campaign report {args.out}\n")
    return 1 if failed else 0
