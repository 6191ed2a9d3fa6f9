"""``lipgen campaign report DIR``: one report over every item of a campaign.

The Table 5.1 analogue with its mean and 95% interval over the items (subjects) of each
condition; tracking, triangulation, normalisation, field and NRSfM errors per condition; a
plot of each error against each swept setting; the failed and the slowest items. A condition is
one combination of the swept settings other than the seeds; the seeds are the subjects.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from lipgen._io import atomic_path, atomic_write_bytes, atomic_write_json, strict_json
from lipgen.campaign.store import item_dir, read_index

__all__ = ["collect", "interval", "write_campaign_report", "SUBJECT_KEYS"]

SUBJECT_KEYS = ("seed", "subject_seed", "motion_seed")
"""Swept settings that draw another subject or motion: the report averages over them."""

METRICS = {
    "tracking_virtual_px": "tracking RMS, virtual view (px)",
    "tracking_real_px": "tracking RMS, real view (px)",
    "triangulation_mm": "triangulation RMS (mm)",
    "normalisation_mm": "normalisation RMS (mm)",
    "fields_vs_truth_mm": "reach fields vs true surface, RMS (mm)",
    "nrsfm_e3d": "monocular NRSfM e3D (truth tracks)",
    "nrsfm_tracked_e3d": "monocular NRSfM e3D (tracked)",
}


def interval(values) -> tuple[float, float, float, int]:
    """Mean and a two-sided 95% Student-t interval of the finite ``values``: (mean, lo, hi, n)."""
    from scipy import stats

    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], float)
    n = len(v)
    if n == 0:
        return math.nan, math.nan, math.nan, 0
    m = float(v.mean())
    if n == 1:
        return m, math.nan, math.nan, 1
    half = float(stats.t.ppf(0.975, n - 1) * v.std(ddof=1) / math.sqrt(n))
    return m, m - half, m + half, n


def _item_figures(root: Path, name: str) -> dict:
    d = item_dir(root, name)
    out: dict = {}
    rep = d / "report" / "report.json"
    if rep.is_file():
        s = json.loads(rep.read_text())
        out.update(tracking_virtual_px=s["tracking"]["virtual"]["rms_px"],
                   tracking_real_px=s["tracking"]["real"]["rms_px"],
                   triangulation_mm=s["triangulation"]["rms_mm"],
                   normalisation_mm=s["normalisation"]["rms_mm"],
                   fields_vs_truth_mm=s["fields"]["rms_mm_vs_truth"], table51=s["table51"])
    nr = d / "nrsfm.json"
    if nr.is_file():
        nrsfm = json.loads(nr.read_text())
        out["nrsfm_e3d"] = nrsfm["truth_tracks"]["e3d"]
        if "tracked" in nrsfm:
            out["nrsfm_tracked_e3d"] = nrsfm["tracked"]["e3d"]
    return out


def collect(root) -> dict:
    """The index of campaign ``root`` with each item's figures read from its outputs."""
    root = Path(root)
    index = read_index(root)
    for entry in index["items"]:
        entry["figures"] = _item_figures(root, entry["name"])
        entry["seconds"] = sum(st.get("task_seconds") or 0.0 for st in entry["stages"].values())
        entry["wall_seconds"] = sum(st.get("seconds") or 0.0 for st in entry["stages"].values())
    return index


def _conditions(index: dict) -> tuple[list[str], dict]:
    keys = [k for k in index.get("swept_keys", []) if k not in SUBJECT_KEYS]
    groups: dict = {}
    for e in index["items"]:
        cond = tuple(json.dumps(e["swept"].get(k)) for k in keys)
        groups.setdefault(cond, []).append(e)
    return keys, groups


def _cond_label(keys, cond) -> str:
    return ", ".join(f"{k}={json.loads(v)}" for k, v in zip(keys, cond, strict=True)) or "all items"


def _fmt_ci(m, lo, hi, n) -> str:
    if n == 0:
        return "–"
    if n == 1:
        return f"{m:.4g} (n=1)"
    return f"{m:.4g} [{lo:.4g}, {hi:.4g}]"


def _table51_md(items: list[dict]) -> list[str]:
    tabs = [e["figures"]["table51"] for e in items if "table51" in e["figures"]]
    if not tabs:
        return ["No item was evaluated."]
    from lipgen.evaluate.scoring import ROWS

    rows = [r for r in ROWS if r in tabs[0]] + [r for r in tabs[0] if r not in ROWS]
    cols = list(tabs[0][rows[0]])
    L = [f"Mean [95% interval] over {len(tabs)} item(s), mm² per hidden DOF.", "",
         "| constraints used | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for ref, label in (("vs_truth", "vs TRUE surface"), ("vs_reach", "vs reach fields (thesis's reference)")):
        L.append(f"| *{label}* |" + " |" * len(cols))
        for row in rows:
            cells = [_fmt_ci(*interval(t[row][c][ref] for t in tabs)) for c in cols]
            L.append(f"| {row} | " + " | ".join(cells) + " |")
    return L


def _plots(index: dict, out: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = [k for k in index.get("swept_keys", []) if k not in SUBJECT_KEYS]
    metrics = {m: label for m, label in METRICS.items() if any(e["figures"].get(m) is not None
                                                               for e in index["items"])}
    pics = []
    for key in keys if metrics else ():
        vals = sorted({json.dumps(e["swept"].get(key)) for e in index["items"]})
        numeric = all(isinstance(json.loads(v), int | float) and not isinstance(json.loads(v), bool)
                      for v in vals)
        xs = [json.loads(v) for v in vals] if numeric else list(range(len(vals)))
        cols = min(len(metrics), 3)
        rows = -(-len(metrics) // cols)
        fig, axes = plt.subplots(rows, cols, figsize=(max(3.4 * cols, 6.5), 2.8 * rows), squeeze=False)
        for ax in axes.ravel()[len(metrics):]:
            ax.set_visible(False)
        for ax, (metric, label) in zip(axes.ravel(), metrics.items(), strict=False):
            stats = [interval(e["figures"].get(metric) for e in index["items"]
                              if json.dumps(e["swept"].get(key)) == v) for v in vals]
            m = np.array([s[0] for s in stats])
            lo = np.array([s[1] for s in stats])
            hi = np.array([s[2] for s in stats])
            err = np.vstack([np.nan_to_num(m - lo), np.nan_to_num(hi - m)])
            ax.errorbar(xs, m, yerr=err, marker="o", capsize=3)
            ax.set_title(label, fontsize=8)
            ax.set_xlabel(key, fontsize=8)
            if not numeric:
                ax.set_xticks(xs, [json.loads(v) for v in vals], rotation=30, fontsize=7)
        fig.suptitle(f"error against {key} (mean and 95% interval over the other settings)", fontsize=9)
        fig.tight_layout()
        path = out / f"vs_{key}.png"
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=90)
        plt.close(fig)
        pics.append(path.name)
    return pics




def write_campaign_report(root, out=None, slowest: int = 5) -> Path | str:
    """Write ``report.md``, ``report.json`` and the plots of campaign ``root`` into ``out``
    (default ``root/report``); returns the path of ``report.md``.

    ``root`` may be a store URL (:mod:`lipgen.campaign.remote`): the index and the items'
    scores are downloaded, and the report goes to ``out`` or else into the store's ``report/``
    (then the URL of ``report.md`` is returned).
    """
    from lipgen.campaign.remote import Store, is_uri

    if is_uri(root):
        import tempfile

        store = Store(root)
        with tempfile.TemporaryDirectory(prefix="lipgen-report-") as tmp:
            for f in sorted(store.files("")):
                if f == "campaign.json" or f.endswith(("/report/report.json", "/nrsfm.json")):
                    store.get_file(f, Path(tmp) / f)
            md = write_campaign_report(tmp, out or Path(tmp) / "report", slowest)
            if out is not None:
                return md
            for p in sorted(Path(md).parent.iterdir()):
                store.put_file(p, f"report/{p.name}")
        return f"{root.rstrip('/')}/report/report.md"
    root = Path(root)
    index = collect(root)
    out = root / "report" if out is None else Path(out)
    out.mkdir(parents=True, exist_ok=True)
    keys, groups = _conditions(index)
    items = index["items"]
    status = {s: sum(e["status"] == s for e in items) for s in ("done", "failed", "pending", "running")}
    L = [f"# Campaign {index.get('name', '')}", "",
         f"{len(items)} items: {status['done']} done, {status['failed']} failed, "
         f"{len(items) - status['done'] - status['failed']} not finished. Swept: "
         f"{', '.join(index.get('swept_keys', [])) or 'nothing'}; subjects: the seeds. lipgen "
         f"{index.get('lipgen_version')}.", "", "## Table 5.1 analogue per condition", ""]
    summary: dict = {"conditions": []}
    for cond, members in groups.items():
        L += [f"### {_cond_label(keys, cond)}", ""] + _table51_md(members) + [""]
    L += ["## Errors per condition", "", "Mean [95% interval] over the items of each condition.", "",
          "| condition | items | " + " | ".join(METRICS.values()) + " |", "|---" * (len(METRICS) + 2) + "|"]
    for cond, members in groups.items():
        stats = {m: interval(e["figures"].get(m) for e in members) for m in METRICS}
        L.append(f"| {_cond_label(keys, cond)} | {len(members)} | "
                 + " | ".join(_fmt_ci(*stats[m]) for m in METRICS) + " |")
        named = {k: json.loads(v) for k, v in zip(keys, cond, strict=True)}
        summary["conditions"].append({"condition": named, "items": len(members),
                                      "metrics": {m: dict(zip(("mean", "lo95", "hi95", "n"), stats[m],
                                                              strict=True)) for m in METRICS}})
    pics = _plots(index, out)
    if pics:
        L += ["", "## Error against each swept setting", ""] + [f"![{p}]({p})" for p in pics]
    failed = [e for e in items if e["status"] == "failed"]
    L += ["", "## Failed items", ""]
    if failed:
        L += ["| item | settings swept | stage | error |", "|---|---|---|---|"]
        for e in failed:
            st = next((n for n, s in e["stages"].items() if s["status"] == "failed"), "?")
            err = str(e["stages"].get(st, {}).get("error", "")).replace("|", "/").replace("\n", " ")[:200]
            L.append(f"| {e['name']} | {e['swept']} | {st} | {err} |")
    else:
        L.append("None.")
    order = [s for s in ("generate", "reconstruct", "nrsfm", "train", "evaluate") if s in items[0]["stages"]]
    L += ["", f"## Slowest items (top {slowest})", "",
          "Seconds of work per stage (generate: the simulation and every chunk's rendering, summed over "
          "workers); *wall* is from the first submission to the last result, queueing included.", "",
          "| item | work | wall | " + " | ".join(order) + " |", "|---" * (len(order) + 3) + "|"]
    for e in sorted(items, key=lambda e: -e["seconds"])[:slowest]:
        L.append(f"| {e['name']} | {e['seconds']:.1f} | {e['wall_seconds']:.1f} | " + " | ".join(
            f"{e['stages'][s].get('task_seconds') or 0:.1f}" for s in order) + " |")
    atomic_write_bytes(out / "report.md", ("\n".join(L) + "\n").encode())
    summary["items"] = [{k: e[k] for k in ("name", "swept", "status", "seconds", "wall_seconds", "figures")}
                        for e in items]
    atomic_write_json(out / "report.json", strict_json(summary))
    return out / "report.md"
