"""Running a campaign: every item's stages as tasks, one progress bar, an index kept on disk.

The driver (this process) only schedules: per item it submits ``prepare`` (simulate the subject,
lay out the dataset folder), then one ``render_chunk`` task per ``chunk_frames`` frames, then
reconstruct, NRSfM, train and evaluate, each when its input is written. A failed task fails its
item (recorded with the error; its later stages are skipped) and the other items go on. The
index (``campaign.json``) is rewritten atomically after every stage, so a stopped campaign is
continued with ``resume=True``: finished stages are kept, a dataset resumes at its first
missing frame, and failed items are tried again.
"""

from __future__ import annotations

import datetime as _dt
import logging
import time
import traceback

from lipgen import __version__
from lipgen.campaign.executors import check_address, check_executor, make_executor
from lipgen.campaign.places import place_of
from lipgen.campaign.plan import CampaignPlan
from lipgen.campaign.stages import chunks
from lipgen.campaign.store import FORMAT, SCHEMA, CampaignError, versions

__all__ = ["run_campaign", "item_stages"]

log = logging.getLogger(__name__)


def item_stages(plan: CampaignPlan) -> list[str]:
    """The order of one item's stages (NRSfM after reconstruct, so it can score the tracks too)."""
    order = ("generate", "reconstruct", "nrsfm", "train", "evaluate")
    return [s for s in order if s in plan.stages]


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def _new_index(plan: CampaignPlan) -> dict:
    stages = item_stages(plan)
    return {"format": FORMAT, "schema_version": SCHEMA, "name": plan.name, "fingerprint": plan.fingerprint(),
            "plan": plan.to_dict(), "swept_keys": list(plan.swept_keys), "created": _now(),
            "lipgen_version": __version__, "versions": versions(), "runs": [],
            "items": [{"name": it.name, "settings": it.settings.to_dict(), "swept": it.swept,
                       "status": "pending", "stages": {s: {"status": "pending"} for s in stages}}
                      for it in plan.items]}


class _Item:
    """The driver's view of one item while it runs."""

    def __init__(self, entry: dict, plan: CampaignPlan) -> None:
        self.entry, self.name = entry, entry["name"]
        self.todo = [s for s in item_stages(plan) if entry["stages"][s]["status"] != "done"]
        self.chunks_left = 0
        self.t0 = self.prepare_s = 0.0

    def stage(self) -> str | None:
        return self.todo[0] if self.todo else None


def run_campaign(plan: CampaignPlan, out, executor: str = "ray", address: str | None = None,
                 workers: int | None = None, resume: bool = False, progress: bool = True,
                 dashboard: bool = False) -> dict:
    """Run ``plan`` into folder ``out``; returns the final index (also in ``out/campaign.json``).

    Parameters
    ----------
    plan : CampaignPlan
        From :func:`lipgen.campaign.load_plan`.
    out : path or str
        A new or empty folder, or (``resume``) this plan's earlier campaign; or a store URL
        (``s3://bucket/runs/x``, ``gs://...``, ``file:///...``: any fsspec URL, see
        :mod:`lipgen.campaign.remote`), written object by object.
    executor : {"ray", "local"} or executor
        Ray tasks (embedded local Ray, or the cluster at ``address``), or local processes; or an
        executor already made (:func:`lipgen.campaign.make_executor`), which is left running.
    address : str, optional
        A running Ray cluster (``HOST:PORT``, ``ray://HOST:PORT`` or ``auto``).
    workers : int, optional
        CPUs of the embedded Ray / processes of the local executor (default: all cores).
    resume, progress, dashboard : bool
        Continue a stopped campaign; show one tqdm bar; start Ray's dashboard (embedded Ray).

    Raises
    ------
    CampaignError
        ``out`` is not this campaign's folder, or another campaign holds it; a store URL that
        fsspec does not know, or ``memory://`` (it lives in one process; the workers are others).
    ClusterError
        ``address`` does not answer, or Ray cannot start.
    """
    from tqdm import tqdm

    place = place_of(out)
    if getattr(getattr(place, "store", None), "in_process", False):
        raise CampaignError(f"--out {out}: memory:// lives in this process only, and the campaign's tasks "
                            "run in other processes (what they wrote would be lost); use a folder, file://, "
                            "s3://, gs:// ...")
    if address is not None:
        check_address(address)  # before anything is written
    if isinstance(executor, str):
        check_executor(executor, address, workers)  # --workers 0 or 10^5: not after the index is written
    place.check(plan.fingerprint(), resume)
    place.create()
    with place.lock():
        old = place.check(plan.fingerprint(), resume)  # again, now that no one else can start
        index = _new_index(plan) if old is None else place.read_index()
        for entry in index["items"]:
            if entry["status"] != "done":
                entry["status"] = "pending"
                gen = entry["stages"].get("generate", {})
                redo = gen.get("status") == "done" and place.incomplete(entry["name"], entry["settings"])
                for st in entry["stages"].values():
                    if st["status"] != "done" or redo:  # a dataset that lost files: its stages again
                        st.update(status="pending", error=None)
        run = {"started": _now(), "executor": getattr(executor, "kind", executor), "address": address}
        index["runs"].append(run)
        place.write_index(index)
        items = [_Item(e, plan) for e in index["items"] if e["status"] != "done"]
        total = plan.total_frames
        done_frames = total - sum(it.settings.frames + it.settings.calib_frames for it in plan.items
                                  if index["items"][it.index]["stages"].get("generate", {}).get("status")
                                  != "done")
        own = isinstance(executor, str)
        ex = make_executor(executor, address, workers, plan.retries, dashboard) if own else executor
        run["workers"] = ex.workers
        if ex.dashboard_url:
            log.warning("Ray dashboard: http://%s", ex.dashboard_url)
        bar = tqdm(total=total, initial=done_frames, desc=f"lipgen campaign {plan.name}", unit="frame",
                   disable=not progress)
        try:
            _drive(ex, plan, items, index, place, bar)
        finally:
            bar.close()
            for entry in index["items"]:
                for st in entry["stages"].values():
                    if st["status"] == "running":
                        st["status"] = "interrupted"
            run["finished"] = _now()
            place.write_index(index)
            if own:
                ex.shutdown()
    return index


def _fail(item: _Item, stage: str, exc: BaseException) -> None:
    e = item.entry
    e["status"] = "failed"
    st = e["stages"][stage]
    st.update(status="failed", error=f"{type(exc).__name__}: {exc}",
              traceback="".join(traceback.format_exception(exc))[-4000:],
              seconds=time.perf_counter() - item.t0)
    for later in item.todo[1:]:
        e["stages"][later]["status"] = "skipped"
    item.todo = []
    log.warning("item %s failed at %s: %s", e["name"], stage, st["error"])


def _submit_stage(ex, plan: CampaignPlan, item: _Item, place, pending: dict) -> None:
    stage = item.stage()
    if stage is None:
        item.entry["status"] = "done"
        return
    item.t0 = time.perf_counter()
    item.entry["status"] = "running"
    item.entry["stages"][stage].update(status="running", started=_now())
    if stage == "generate":
        pending[place.submit_prepare(ex, item.name, item.entry["settings"])] = (item, "prepare", 0)
    else:
        options = {"reconstruct": plan.reconstruct, "train": plan.train, "evaluate": plan.train,
                   "nrsfm": plan.nrsfm}[stage]
        pending[place.submit_stage(ex, stage, item.name, options)] = (item, stage, 0)


def _finish_stage(ex, plan, item: _Item, stage: str, summary: dict, index, place, pending) -> None:
    st = item.entry["stages"][stage]
    st.update(status="done", seconds=time.perf_counter() - item.t0, finished=_now(), error=None, **summary)
    item.todo.pop(0)
    _submit_stage(ex, plan, item, place, pending)
    place.write_index(index)


def _drive(ex, plan: CampaignPlan, items: list[_Item], index: dict, place, bar) -> None:
    pending: dict = {}
    for item in items:
        _submit_stage(ex, plan, item, place, pending)
    gen: dict = {}  # per item: chunk results of its generate stage
    while pending:
        for h in ex.wait(list(pending)):
            item, kind, n = pending.pop(h)
            if item.entry["status"] == "failed":
                continue  # a sibling chunk already failed this item
            try:
                value = ex.result(h)
            except Exception as exc:  # the task's own error: this item fails, the others go on
                _fail(item, "generate" if kind in ("prepare", "chunk") else kind, exc)
                place.write_index(index)
                continue
            if kind == "prepare":
                ctx, jobs, item.prepare_s = value
                s = item.entry["settings"]
                bar.update(s["frames"] + s["calib_frames"] - len(jobs))
                gen[item.entry["name"]] = []
                if not jobs:
                    _finish_stage(ex, plan, item, "generate", {"chunks": 0, "task_seconds": item.prepare_s},
                                  index, place, pending)
                    continue
                ref = ex.put(ctx)
                parts = chunks([list(j) for j in jobs], plan.chunk_frames)
                item.chunks_left = len(parts)
                for part in parts:
                    pending[place.submit_chunk(ex, item.name, ref, part)] = (item, "chunk", len(part))
            elif kind == "chunk":
                bar.update(value["frames"])
                gen[item.entry["name"]].append(value)
                item.chunks_left -= 1
                if item.chunks_left == 0:
                    res = gen.pop(item.entry["name"])
                    peaks = [r["peak_rss_mib"] for r in res if r["peak_rss_mib"] is not None]
                    _finish_stage(ex, plan, item, "generate", {
                        "chunks": len(res), "render_seconds": sum(r["seconds"] for r in res),
                        "render_cpu_seconds": sum(r.get("cpu_seconds", 0.0) for r in res),
                        "task_seconds": item.prepare_s + sum(r["seconds"] for r in res),
                        "workers": len({r["pid"] for r in res}),
                        "peak_rss_mib": max(peaks) if peaks else None}, index, place, pending)
            else:
                _finish_stage(ex, plan, item, kind, value, index, place, pending)
            done = sum(e["status"] == "done" for e in index["items"])
            failed = sum(e["status"] == "failed" for e in index["items"])
            bar.set_postfix_str(f"items {done}/{len(index['items'])} done, {failed} failed", refresh=False)
