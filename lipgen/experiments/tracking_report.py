"""The report of :func:`lipgen.experiments.tracking.run_tracking`: ``tracking.md``,
``tracking.json`` and ``tracking.png``."""

from __future__ import annotations

import datetime as _dt
import json
from pathlib import Path

import numpy as np

from lipgen._io import atomic_path, atomic_write_bytes, atomic_write_json, strict_json
from lipgen.experiments.tracking import TARGETS

__all__ = ["write_tracking_report", "REPORT_FILES"]

REPORT_FILES = ("tracking.md", "tracking.json", "tracking.png")
"""What :func:`write_tracking_report` writes into its folder."""

_TARGET_NAMES = {"rms_px": f"RMS <= {TARGETS['rms_px']} px in each view", "accepted_share":
                 f"accepted >= {100 * TARGETS['accepted_share']:.0f} %", "over_3px": "none > 3 px"}

_VIEW_NAMES = {"virtual": "mirror (virtual)", "real": "direct (real)"}


def _pct(x: float) -> str:
    return "n/a" if not np.isfinite(x) else f"{100 * x:.1f}"


def _num(x: float, decimals: int = 3) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{decimals}f}"


def _met(t: dict) -> str:
    return " / ".join("met" if t[k] else "**not met**" for k in TARGETS)


def _row(name: str, f: dict) -> str:
    pv = f["per_view"]
    return (f"| {name} | {_pct(f['accepted_share'])} | {_pct(f['within_3px_share'])} | {f['over_3px']} | "
            f"{_num(f['rms_px'])} | {_num(pv['virtual']['rms_px'])} | {_num(pv['real']['rms_px'])} | "
            f"{_num(f['p95_px'])} | {f['accepted']} / {f['visible']} | {_markers_pct(f)} | {f['rejected']} | "
            f"{f['lost']} | "
            f"{_num(f['tracking_cpu_ms_per_frame'], 0)} | {_met(f['targets'])} |")


def _markers_pct(f: dict) -> str:
    m = f.get("markers_only")
    return "n/a" if m is None else _pct(m["accepted_share"])




def _picture(result: dict, out: Path) -> str:
    """Left: each set's visible sightings split into accepted within 3 px, accepted over 3 px,
    rejected and lost. Right: per view (all sets), the share of the accepted sightings at or above each
    error."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sets = result["sets"]
    names = [s["label"] for s in sets] + ["all"]
    figs = [*sets, result["pooled"]]
    parts = [("accepted, <= 3 px", "within_3px", "tab:green"), ("accepted, > 3 px", "over_3px", "tab:red"),
             ("rejected", "rejected", "tab:orange"), ("lost", "lost", "0.6")]
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 4.2), gridspec_kw={"width_ratios": [1.3, 1]})
    x = np.arange(len(figs))
    bottom = np.zeros(len(figs))
    for label, key, color in parts:
        h = np.array([100 * f[key] / max(f["visible"], 1) for f in figs])
        ax.bar(x, h, bottom=bottom, color=color, label=label, width=0.7)
        bottom += h
    for i, f in enumerate(figs):
        ax.text(i, 101, f"{f['over_3px']}", ha="center", va="bottom", fontsize=8, color="tab:red")
    ax.axhline(100 * TARGETS["accepted_share"], color="k", ls="--", lw=1,
               label=f"target {100 * TARGETS['accepted_share']:.0f} % accepted")
    ax.set_xticks(x, names, rotation=30, ha="right")
    ax.set_ylim(0, 108)
    ax.set_ylabel("share of the visible sightings (%)")
    ax.set_title("sightings per set (red figures: accepted > 3 px)", fontsize=10)
    ax.legend(fontsize=8, loc="lower left")
    for view, color in (("virtual", "tab:purple"), ("real", "tab:blue")):
        e = np.sort(np.concatenate([np.asarray(er[view]) for er in result["errors"]]))
        if len(e):  # the share above each error: the tail (> 3 px) stays visible on a log scale
            above = 100 * (len(e) - np.arange(len(e))) / len(e)
            bx.step(np.maximum(e, 1e-3), above, where="post", color=color,
                    label=f"{_VIEW_NAMES[view]} ({len(e)} accepted)")
    for v, ls in ((TARGETS["rms_px"], ":"), (3.0, "--")):
        bx.axvline(v, color="k", ls=ls, lw=1)
    bx.set_xscale("log")
    bx.set_yscale("log")
    bx.set_xlabel("tracking error of an accepted sighting (px)")
    bx.set_ylabel("share of the accepted sightings at or above it (%)")
    bx.set_title("error distribution, all sets (lines at 0.5 and 3 px)", fontsize=10)
    bx.grid(alpha=0.3, which="both")
    bx.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    path = out / "tracking.png"
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return path.name


def _spread_lines(sp: dict, n: int) -> list[str]:
    names = {"accepted_share": ("accepted share (%)", 100, 1),  # label, factor, decimals
             "within_3px_share": ("within 3 px (%)", 100, 1), "over_3px": ("accepted > 3 px (count)", 1, 1),
             "rms_px": ("RMS, both views (px)", 1, 3), "rms_px_virtual": ("RMS, mirror view (px)", 1, 3),
             "rms_px_real": ("RMS, direct view (px)", 1, 3),
             "tracking_cpu_ms_per_frame": ("tracking CPU (ms / frame)", 1, 0)}
    lines = [f"## Mean and spread over the {n} sets", "",
             "Each set's figure, then the mean, standard deviation (n - 1) and range over the sets.", "",
             "| figure | mean | std | min | max |", "|---|---|---|---|---|"]
    for key, (label, k, dec) in names.items():
        s = sp[key]
        cells = [_num(k * s[c], dec) for c in ("mean", "std", "min", "max")]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return lines + [""]


def _view_lines(result: dict) -> list[str]:
    lines = ["## Per view (the tracking table of `lipgen evaluate`)", "",
             "| set | view | RMS (px) | 95th pct (px) | accepted (%) | accepted | rejected | lost | "
             "> 3 px | false sightings |", "|---|---|---|---|---|---|---|---|---|---|"]
    for s in result["sets"]:
        for view, t in s["per_view"].items():
            lines.append(f"| {s['label']} | {_VIEW_NAMES[view]} | {_num(t['rms_px'])} | "
                         f"{_num(t['p95_px'])} | {_pct(t['tracked_share'])} | {t['accepted']} | "
                         f"{t['rejected']} | {t['lost']} | {t['wrong_over_3px']} | {t['false_sightings']} |")
    return lines + [""]


def _origin(s: dict) -> str:
    """Where a set came from: given, generated by this run, or reused (and at which commit)."""
    if s["reused"] is None:
        return ""
    if not s["reused"]:
        return " (generated by this run)"
    made_by = s.get("generated_by") or {}
    commit = made_by.get("git_commit")
    made = (commit[:12] + (" with uncommitted changes" if made_by.get("git_dirty") else "") if commit
            else "unknown: no sidecar")
    return f" (reused from the work folder; generated at commit {made})"


def write_tracking_report(result: dict, out, note: str | None = None) -> Path:
    """Write :data:`REPORT_FILES` into folder ``out`` (created); returns the path of ``tracking.md``.
    ``note``: a paragraph put under the title (e.g. where these seeds were used before)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    pic = _picture(result, out)
    st, code, load, pooled = result["settings"], result["code"], result["load"], result["pooled"]
    sets = result["sets"]
    source = (f"existing datasets {', '.join(st['datasets'])}" if st["datasets"] else
              f"preset `{st['preset']}`, seeds {', '.join(map(str, st['seeds']))}, {st['frames']} frames"
              + (f", {st['size'][0]}x{st['size'][1]}" if st.get("size") else "")
              + (f", {st['calib_frames']} calibration frames" if st.get("calib_frames") else "")
              + (f", {st['lens_frames']} of them lens frames" if st.get("lens_frames") is not None else ""))
    met_all = sum(all(s["targets"].values()) for s in sets)
    dirty = " (with uncommitted changes)" if code["git_dirty"] else ""
    commit = (code["git_commit"] or "unknown")[:12] + dirty
    L = ["# Tracking against the truth (issue 15's targets)", ""]
    if note:
        L += [note, ""]
    L += [f"Sets: {source}. Code: lipgen {code['lipgen']}, commit {commit}. Run "
          f"{_dt.datetime.now(_dt.UTC).strftime('%Y-%m-%d %H:%M')} UTC, {load['seconds']:.0f} s wall, "
          f"{load['cpu_seconds']:.0f} s CPU of this process; load average {load['start'][0]:.2f} at the "
          f"start, {load['end'][0]:.2f} at the end; BLAS threads {load['threads']}.", "",
          "Every sighting the truth says is visible is *accepted* (seen in both views with agreeing rays, "
          "not a pose outlier of the normalisation), *rejected* (found, but the views disagree or a pose "
          "outlier) or *lost* (not found in that view): the definitions of `lipgen evaluate` "
          "(`lipgen.evaluate.scoring.sighting_errors`, `tracking_table`). Shares are of the visible "
          "sightings of both views; *within 3 px*: accepted and at most 3 px from the true projection; RMS "
          "and the 95th percentile over the accepted sightings. Tracking CPU: this process's CPU time in "
          "the tracking step (`lipgen.recon.pipeline`, `info['cpu_seconds']`; reading the frames included, "
          "about 9 ms of it per hard frame) per frame. The visible sightings include the nose (the last "
          "of the P + 1 marks, one per frame and view); *markers only* is the accepted share without it.",
          "",
          f"Targets (issue 15): {', '.join(_TARGET_NAMES.values())} (the mirror and the direct view both "
          "meet it); the last column says met / not met in that order.", "",
          "| set | accepted (%) | within 3 px (%) | > 3 px | RMS both views (px) | RMS mirror | RMS direct | "
          "95th pct (px) | accepted / visible | markers only: accepted (%) | rejected | lost | "
          "tracking CPU (ms / frame) | targets |",
          "|---" * 14 + "|"]
    L += [_row(s["label"] + (" (not reconstructed)" if "not_reconstructed" in s else ""), s) for s in sets]
    L += [_row("**all sets pooled**", pooled), ""]
    failed = [s for s in sets if "not_reconstructed" in s]
    if failed:
        L += [f"**Not reconstructed** ({len(failed)} of {len(sets)} sets; `lipgen reconstruct` stops on "
              "them, so their visible sightings count as not accepted, with no rejected or lost counts): "
              + "; ".join(f"{s['label']}: {s['not_reconstructed']['reason']}" for s in failed) + ".", ""]
    verdict = "met" if all(pooled["targets"].values()) else "not met"
    L += [f"**Overall**: the targets are {verdict} on the pooled sightings ({_met(pooled['targets'])}); "
          f"{met_all} of {len(sets)} sets meet all three.", ""]
    if len(sets) >= 2:
        L += _spread_lines(result["spread"], len(sets))
    if len(sets) < 3:
        L += [f"Issue 15 asks for at least 3 seeds; this run has {len(sets)}.", ""]
    L += [f"![sightings per set and error distribution]({pic})", "",
          "Left: each set's visible sightings (both views) as accepted within 3 px, accepted over 3 px "
          "(count above the bar), rejected and lost; right: per view, all sets together, the share of the "
          "accepted sightings whose error is at or above each value (log scales, so that the few over 3 px "
          "show).", ""]
    L += _view_lines(result)
    L += ["Datasets: " + "; ".join(f"{s['label']} `{s['dataset']}`" + _origin(s) for s in sets) + ".", ""]
    if sets:
        work, first = st["work"], sets[0]
        rec, model = f"{work}/{first['label']}.recon.npz", f"{work}/{first['label']}.model.npz"
        L += [f"Reconstructions: `LABEL.recon.npz` in the work folder `{work}`. The per-view table above "
              "is `lipgen evaluate`'s tracking table (the `tracking` entry of its `report.json`); for the "
              f"set {first['label']} (the others alike; evaluate also needs a trained model):", "",
              f"    lipgen train {rec} --out {model}",
              f"    lipgen evaluate {first['dataset']} --model {model} --recon {rec} "
              f"--out {work}/{first['label']}.evaluate", ""]
    atomic_write_bytes(out / "tracking.md", ("\n".join(L) + "\n").encode())
    public = {k: v for k, v in result.items() if k != "errors"} | {"note": note}
    atomic_write_json(out / "tracking.json", strict_json(json.loads(json.dumps(public, default=float))))
    return out / "tracking.md"
