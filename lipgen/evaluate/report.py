"""The end-to-end report: ``REPORT/report.md``, ``report.json`` and pictures (matplotlib, Agg).

Built from the figures of :func:`lipgen.evaluate.scoring`; see :func:`write_report`.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from lipgen._io import atomic_path, atomic_write_bytes, atomic_write_json
from lipgen.evaluate.scoring import ROWS
from lipgen.rig.camera import VIEWS

__all__ = ["write_report", "nrsfm_section", "REPORT_FILES"]

log = logging.getLogger(__name__)

REPORT_FILES = ("report.md", "report.json", "modes.png", "frame.png", "overlay.png", "variance.png",
                "conditions.png")
"""Every file :func:`write_report` may write into its folder."""


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> str:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")
    _plt().close(fig)
    return path.name


_METHOD_NAMES = {
    "thesis": "thesis §3 lip planes",
    "least-force": "least-force head pose about the nose",
    "least-strain": "least-strain-energy head pose about the nose",
    "procrustes": "Procrustes head pose about the nose",
}


def _fmt(x, digits=3) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{digits}g}"


def _mode_pictures(model, mesh, out: Path) -> str:
    """Mean displacement and the first modes (+2 sd), front (x-y) and side (z-y), coloured by
    the displacement magnitude, on the deformed mesh."""
    plt = _plt()
    V, Fc = mesh.vertices, mesh.faces
    k = min(3, len(model.components_))
    shapes = [("mean displacement", model.mean_.reshape(-1, 3))]
    for i in range(k):
        amp = 2.0 * np.sqrt(model.explained_variance_[i])
        shapes.append((f"mode {i + 1}: +2 sd ({100 * model.explained_variance_ratio_[i]:.1f}%)",
                       amp * model.components_[i].reshape(-1, 3)))
    fig, axes = plt.subplots(2, k + 1, figsize=(4 * (k + 1), 7), squeeze=False)
    for j, (title, U) in enumerate(shapes):
        W = V + (U if j == 0 else model.mean_.reshape(-1, 3) + U)
        mag = np.linalg.norm(U, axis=1)
        for row, (a, name) in enumerate(((0, "front x-y"), (2, "side z-y"))):
            ax = axes[row, j]
            tpc = ax.tripcolor(W[:, a], W[:, 1], Fc, mag, shading="gouraud", cmap="viridis")
            ax.triplot(W[:, a], W[:, 1], Fc, color="white", lw=0.2, alpha=0.5)
            ax.set_aspect("equal")
            ax.set_title(f"{title}\n{name}" if row == 0 else name, fontsize=9)
            fig.colorbar(tpc, ax=ax, shrink=0.7, label="mm")
    return _save(fig, out / "modes.png")


def _frame_picture(ds, recon, frame: int, out: Path) -> str:
    plt = _plt()
    img = ds[frame].image
    truth = ds[frame].truth
    h, w = img.shape[:2]
    fig, ax = plt.subplots(figsize=(w / 60, h / 60))
    ax.imshow(img, interpolation="nearest")
    for v, view in enumerate(VIEWS):
        t_uv = ds.rig.to_raw(view, truth["uv"][v])
        ax.scatter(t_uv[:, 0], t_uv[:, 1], s=70, facecolors="none", edgecolors="lime", lw=1.0,
                   label="truth" if v == 0 else None)
        d_uv = ds.rig.to_raw(view, recon.uv[v, frame])
        ax.scatter(d_uv[:, 0], d_uv[:, 1], s=14, marker="+", color="red", lw=1.0,
                   label="tracked" if v == 0 else None)
    marks = np.vstack([ds.rig.to_raw(view, truth["uv"][v]) for v, view in enumerate(VIEWS)])
    top, bottom = np.nanmin(marks[:, 1]), np.nanmax(marks[:, 1])
    ax.set_ylim(min(h - 0.5, bottom + 40), max(-0.5, top - 40))   # the band of the face's marks
    ax.set_title(f"raw frame {frame}: tracked (red +) and true (green o) marks")
    ax.legend(loc="lower right", fontsize=8)
    ax.axis("off")
    return _save(fig, out / "frame.png")


def _overlay_picture(model, mesh, recon, true_fields, frame: int, out: Path) -> str:
    from lipgen.fem import dofs as node_dofs

    plt = _plt()
    from matplotlib.collections import LineCollection

    from lipgen.recon.restsource import rest_markers

    seen = np.flatnonzero(recon.visible[frame, :8])
    rest = mesh.vertices
    d = node_dofs(mesh.markers[seen], "xyz")
    shift = rest[mesh.markers] - rest_markers(recon, mesh)  # markers drawn on the model's rest
    y = (recon.markers[frame, seen] + shift[seen] - rest[mesh.markers[seen]]).ravel()
    est = model.llse(d).estimate(y)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    for ax, (a, b, name) in zip(axes, ((0, 1, "front (x-y)"), (2, 1, "side (z-y)")), strict=True):
        for U, style, label in ((true_fields[frame], dict(color="k", lw=0.5), "true surface"),
                                (est, dict(color="tab:red", lw=0.5, ls="--"), "LLSE, 10 modes, 8 points")):
            W = rest + U
            # every triangle's outline, as one collection (a line per triangle cost seconds)
            loops = mesh.faces[:, [0, 1, 2, 0]]
            ax.add_collection(LineCollection(np.stack([W[loops, a], W[loops, b]], axis=-1), **style))
            ax.plot([], [], label=label, **style)
        drawn = recon.markers[frame, seen] + shift[seen]
        ax.plot(drawn[:, a], drawn[:, b], "o", color="tab:blue", ms=4,
                label="observed markers")
        ax.set_aspect("equal")
        ax.set_title(name)
    axes[0].legend(fontsize=8, loc="lower left")
    rms = np.sqrt(np.mean(np.sum((est - true_fields[frame]) ** 2, axis=1)))
    fig.suptitle(f"test frame {frame}: reconstruction vs truth (node RMS {rms:.2f} mm)")
    return _save(fig, out / "overlay.png")


def _variance_picture(s: dict, out: Path) -> str:
    plt = _plt()
    cum = 100 * np.asarray(s["variance"]["cumulative_share"])
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(np.arange(1, len(cum) + 1), cum, "o-", ms=3)
    ax.axvline(10, color="gray", ls=":")
    ax.set_xlabel("number of modes")
    ax.set_ylabel("variance captured (%)")
    ax.set_ylim(min(50, cum[0] - 5), 100.5)
    ax.grid(alpha=0.3)
    return _save(fig, out / "variance.png")


def _table51_md(t: dict, unit_mm: float) -> list[str]:
    cols = list(next(iter(t.values())))
    lines = ["| constraints used | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for ref, label in (("vs_reach", "vs reach fields (thesis's reference)"), ("vs_truth", "vs TRUE surface")):
        lines.append(f"| *{label}, mm²* |" + " |" * len(cols))
        for row in ROWS:
            lines.append(f"| {row} | " + " | ".join(_fmt(t[row][c][ref]) for c in cols) + " |")
    lines.append(f"| *vs reach fields, thesis units² (1 unit = {unit_mm:.2f} mm)* |" + " |" * len(cols))
    for row in ROWS:
        cells = (_fmt(t[row][c]["vs_reach"] / unit_mm ** 2) for c in cols)
        lines.append(f"| {row} | " + " | ".join(cells) + " |")
    return lines


def nrsfm_section(ds, recon=None, view: str = "real", min_frames: int = 3) -> str:
    """Monocular non-rigid SfM (:func:`lipgen.nrsfm.evaluate_on_dataset`, K chosen by the method)
    on one view of the dataset, from the truth's projections and, given ``recon``, from the
    tracker's output.

    Marks the tracker saw in fewer than ``min_frames`` frames are left out of the second run (and
    named); a run that cannot be computed says why, and the rest is still written.
    """
    from lipgen import nrsfm
    from lipgen.errors import LipgenError
    from lipgen.recon.track import LOST

    path = ds.path if hasattr(ds, "path") else ds

    def attempt(what, **kw):
        try:
            # K chosen by the method (rank by rotation smoothness, depth by consensus): a fixed K
            # can fall below the flat baseline on these nearly rigid clips (the demo: K = 2 0.480,
            # flat 0.442, auto 0.436).
            return nrsfm.evaluate_on_dataset(path, view=view, k="auto", **kw)["markdown"]
        except (ValueError, LipgenError, np.linalg.LinAlgError) as exc:
            log.warning("NRSfM on %s not computed: %s", what, exc)
            return f"**Monocular NRSfM on {what}: not computed** ({exc})."

    parts = [attempt("the truth's projections")]
    if recon is not None:
        v = list(VIEWS).index(view)
        seen = np.isfinite(recon.uv[v]).all(axis=-1) & (recon.status[v] != LOST)
        count = seen.sum(0)
        keep = np.flatnonzero(count >= min_frames)
        if len(keep) < len(count):
            names = list(recon.info.get("marker_names", [])) + ["nose"]
            dropped = ", ".join(f"{names[j] if j < len(names) else j} ({int(count[j])} frames)"
                                for j in np.flatnonzero(count < min_frames))
            parts.append(f"Left out of the tracked run: marks tracked in fewer than {min_frames} frames of "
                         f"the {view} view: {dropped}.")
        if len(keep) < 3:
            parts.append(f"**Monocular NRSfM on the tracks: not computed** (only {len(keep)} marks tracked "
                         f"in {min_frames} or more frames of the {view} view).")
        else:
            parts.append(attempt("the tracks", uv=recon.uv[v], seen=seen, marks=keep))
    parts.append("The head turns by only a few degrees in these sequences, so depth is weakly "
                 "observable from one view; the flat score is the baseline to beat.")
    return "\n\n".join(parts)


def _conditions_picture(ds, frame: int, out: Path) -> str | None:
    """The report's frame beside the same frame as the ``easy`` preset films it, when the dataset
    was made otherwise (None for an easy dataset, or without pyrender: logged)."""
    from lipgen.dataset.pictures import preset_of, save_beside_easy
    from lipgen.errors import LipgenError

    if preset_of(ds) == "easy" or "vertices" not in ds[frame].truth:
        return None
    try:
        return save_beside_easy(ds, frame, out / "conditions.png").name
    except (ImportError, LipgenError) as exc:  # no pyrender / no OpenGL: the report goes on without it
        log.warning("no picture beside the easy preset: %s", exc)
        return None


def _displacement_md(s: dict) -> list[str]:
    d = s.get("displacements")
    if d is None:
        return []
    cells = ", ".join(f"{k} {_fmt(d[k]['rms_mm'])} / {_fmt(d[k]['offset_rms_mm'])} / "
                      f"{_fmt(d[k]['after_offset_rms_mm'])}" for k in ("train", "test"))
    model = (f" The model was trained on fields measured from {d['model_rest']}." if d.get("model_rest")
             else "")
    return [f"- Marker displacements, measured from {d['rest']} (that rest is "
            f"{_fmt(d['all']['rest_rms_mm'])} mm RMS from the subject's true rest), against the true "
            f"displacements from the subject's own rest, mm RMS / each marker's constant offset (RMS over "
            f"the markers) / after the offset: "
            f"{cells}.{model}"]


def write_report(out, s: dict, ds, model, recon, mesh, extra: dict | None = None) -> Path:
    """Write ``report.md``, ``report.json`` and the pictures into folder ``out``."""
    from lipgen.evaluate.metric import ERROR_DEFINITION
    from lipgen.recon.crosscheck import tracking_lines

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    truth_fields = s["_true_fields"]
    test = s["split"]["test"]
    pics = {"modes": _mode_pictures(model, mesh, out), "variance": _variance_picture(s, out),
            "frame": _frame_picture(ds, recon, test[0] if test else 0, out)}
    if test:
        pics["overlay"] = _overlay_picture(model, mesh, recon, truth_fields, test[0], out)
    beside = _conditions_picture(ds, test[0] if test else 0, out)
    if beside:
        pics["conditions"] = beside
    cal = s["calibration"]
    tri, nrm, fld = s["triangulation"], s["normalisation"], s["fields"]
    L = ["# lipgen end-to-end report", "",
         f"Dataset `{recon.info['dataset']}`: {s['frames']} frames, {s['markers']} markers + nose. "
         f"Model mesh `{recon.info['mesh_source']}` ({recon.info['n_nodes']} nodes). Train frames: "
         f"{s['split']['train']}; test frames: {test}.", "",
         "## Calibration (chessboard, one camera + one mirror)", "",
         f"Reprojection RMS: {_fmt(cal['rms_px']['all'])} px (virtual {_fmt(cal['rms_px']['virtual'])}, real "
         f"{_fmt(cal['rms_px']['real'])}).", "",
         "| view | focal error fx, fy (px) | principal point (px) | rotation (deg) | centre (mm) |",
         "|---|---|---|---|---|"]
    for v in VIEWS:
        c = cal["vs_truth"][v]
        L.append(f"| {v} | {_fmt(c['focal_px'][0])}, {_fmt(c['focal_px'][1])} | "
                 f"{_fmt(c['principal_point_px'])} | {_fmt(c['rotation_deg'])} | {_fmt(c['center_mm'])} |")
    rel = cal["vs_truth"]["relative"]
    L += ["", f"Real-to-virtual pose: rotation error {_fmt(rel['rotation_deg'])} deg, baseline error "
          f"{_fmt(rel['baseline_mm'])} mm.", "",
          "## Tracking (vs the true projections, where the dot is visible)", "",
          "Of the sightings the truth says are visible: *accepted* (seen in both views with agreeing "
          "rays, not a pose outlier), *rejected* (seen, but the views disagree or a pose outlier) and "
          "*lost* (not found in this view). RMS, 95th percentile and > 3 px are over accepted sightings.",
          "",
          "| view | RMS (px) | 95th pct (px) | accepted share | accepted | rejected | lost | > 3 px | "
          "false sightings |",
          "|---|---|---|---|---|---|---|---|---|"]
    for v in VIEWS:
        t = s["tracking"][v]
        L.append(f"| {v} | {_fmt(t['rms_px'])} | {_fmt(t['p95_px'])} | {_fmt(t['tracked_share'])} | "
                 f"{t.get('accepted', 'n/a')} | {t.get('rejected', 'n/a')} | {t.get('lost', 'n/a')} | "
                 f"{t['wrong_over_3px']} | {t['false_sightings']} |")
    for line in tracking_lines(recon.info):
        L += ["", line]
    never = recon.info.get("sightings", {}).get("never_tracked", [])
    if never:
        L += ["", "**Never tracked** (whole sequence):", ""]
        L += [f"- {n['mark']} in the {n['view']} view: {n['reason']}" for n in never]
    unaccepted = recon.info.get("sightings", {}).get("never_accepted", [])
    if unaccepted:
        L += ["", "**Never accepted** (no frame with both views agreeing; the fields reach the other "
              "markers):", ""]
        L += [f"- {n['mark']}: {n['reason']}" for n in unaccepted]
    names = list(recon.info["marker_names"]) + ["nose"]
    L += ["", "Per mark (px RMS virtual / real; triangulation mm RMS):", "",
          "| mark | virtual | real | 3-D |", "|---|---|---|---|"]
    for j, name in enumerate(names):
        L.append(f"| {name} | {_fmt(s['tracking']['virtual']['per_mark_rms_px'][j])} | "
                 f"{_fmt(s['tracking']['real']['per_mark_rms_px'][j])} | {_fmt(tri['per_mark_rms_mm'][j])} |")
    L += ["", "## Triangulation and normalisation", "",
          f"- 3-D marker error after triangulation: **{_fmt(tri['rms_mm'])} mm RMS** (max "
          f"{_fmt(tri['max_mm'])} mm) over the {100 * tri['visible_share']:.1f}% of marker sightings seen in "
          f"both views; median ray gap {_fmt(tri['ray_gap_median_mm'])} mm.",
          f"- Normalisation ({_METHOD_NAMES.get(nrm.get('method', 'thesis'), nrm.get('method'))}) error, "
          f"normalised markers vs the true model-frame marks: **{_fmt(nrm['rms_mm'])} mm RMS**, "
          + (f"at the rig's metric scale (scale 1; the head rotation from {nrm['metric_reference']}; its "
             f"reference frame {nrm['reference_frame']})" if nrm.get("metric_reference") else
             f"with the scale fitted on frame {nrm['reference_frame']} (the most neutral-looking frame; the "
             "thesis used the first)")
          + f". The same method on the exact world marks: {_fmt(nrm['exact_input_rms_mm'])} mm, what "
          "the method itself costs (the head turns by up to "
          f"{_fmt(nrm['head_rotation_deg_max'], 2)} deg here). The thesis's §3 lip-plane method on the exact "
          "marks, for comparison: "
          + ", ".join(f"{_fmt(v)} mm ({k})" for k, v in nrm["thesis_exact_input_rms_mm"].items())
          + f". Reference-frame fit residual {_fmt(nrm['fit_rms_mm'])} mm, scale {_fmt(nrm['scale'], 4)}"
          + (f"; {nrm['outliers']} marker sighting(s) left out of the pose fits (and of the fields) as "
             "mis-measured." if nrm.get("method", "thesis") != "thesis" else "."),
          f"- Reach fields (training data) vs the true surface: {_fmt(fld['rms_mm_vs_truth'])} mm RMS per "
          f"node (the true displacement itself is {_fmt(fld['true_rms_displacement_mm'])} mm RMS; reach from "
          f"the TRUE model-frame markers, the model's own floor, "
          f"{_fmt(fld['reach_from_true_markers_rms_mm'])} mm); "
          f"{fld['frames_without_field']} frame(s) without a field.", *_displacement_md(s), "",
          "## Table 5.1 on these data (mean squared error per hidden DOF over the test frames)", "",
          f"Error: {ERROR_DEFINITION}.", ""]
    L += _table51_md(s["table51"], s["thesis_unit_mm"])
    if "combined_choice" in s:
        cc = s["combined_choice"]
        prior = {"force": "K_s⁻²", "energy": "K_s⁻¹"}.get(cc["kind"], cc["kind"])
        L += ["", f"Combined model (§6.1): physical prior {prior} and marker-noise variance "
              f"{_fmt(cc['noise_variance_mm2'])} mm² (RMS {_fmt(cc['noise_variance_mm2'] ** 0.5)} mm per "
              "coordinate), chosen from the training frames' fields by 5-fold cross-validated marginal "
              f"likelihood (`CombinedModel.fit`; its residual variance there: {_fmt(cc['residual_share'])} "
              "of the learned variance at the markers). Its estimates use that noise variance and weigh "
              "a log-uniform grid of residual variances per frame by the frame's own markers "
              "(`CombinedModel.mixture`). The other columns treat the markers as exact."]
    var = s["variance"]
    cum = var["cumulative_share"][:10]
    L += ["", f"Variance captured by 10 modes: **{100 * var['ten_modes']:.2f}%** (thesis: 99.2%).", "",
          "| modes | " + " | ".join(str(i + 1) for i in range(len(cum))) + " |",
          "|---" * (len(cum) + 1) + "|",
          "| variance captured (%) | " + " | ".join(f"{100 * c:.2f}" for c in cum) + " |", "",
          f"![variance captured]({pics['variance']})", "", "## Pictures", "",
          f"![mean and first modes]({pics['modes']})", "", f"![raw frame]({pics['frame']})", ""]
    if "overlay" in pics:
        L += [f"![reconstruction vs truth]({pics['overlay']})", ""]
    if "conditions" in pics:
        L += ["The same frame as filmed here (left) and as the `easy` preset films it (right): the "
              "difference is what this dataset's conditions (head, mouth, ink, light, lens, sensor) add.",
              "", f"![this dataset beside the easy preset]({pics['conditions']})", ""]
    for title, body in (extra or {}).items():
        L += [f"## {title}", "", body, ""]
    atomic_write_bytes(out / "report.md", ("\n".join(L) + "\n").encode())
    public = {k: v for k, v in s.items() if not k.startswith("_")}
    public["extra"] = extra or {}
    atomic_write_json(out / "report.json", json.loads(json.dumps(public, default=float)))
    return out / "report.md"
