"""The Table 5.1 report: markdown tables (mm² and thesis units²), JSON figures and pictures."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lipgen._io import atomic_path, atomic_write_bytes, atomic_write_json
from lipgen.experiments.table51_protocol import COLUMNS, SHARES

__all__ = ["write_report", "report_files", "THESIS_TABLE"]

THESIS_TABLE = {"xyz (8 points)": (1.10e-3, 7.80e-4), "yz (16 points)": (7.13e-4, 4.38e-4),
                "xy (16 points)": (6.70e-3, 7.50e-3)}
"""Thesis Table 5.1 (normalised units², first 10 modes / full sample covariance)."""

_LABEL = {"modes": "10 modes", "full": "full cov.", "physics_force": "physics K⁻² (reach)",
          "physics_energy": "physics K⁻¹", "combined": "combined", "combined_fixed": "combined (one σ²)",
          "combined_energy": "combined (K⁻¹, one σ²)"}


def _fmt(x: float) -> str:
    return f"{x:.2e}"


def _verdict(table: dict) -> list[str]:
    """Whether the combined model beats the best learned-only and physics-only column, per row."""
    out = []
    for row, v in table.items():
        learned = min(("modes", "full"), key=lambda c: v[c]["truth"])
        physics = min(("physics_force", "physics_energy"), key=lambda c: v[c]["truth"])
        c, lv, pv = v["combined"]["truth"], v[learned]["truth"], v[physics]["truth"]
        ok = c < min(lv, pv)
        verb = 'beats' if ok else 'does NOT beat'
        out.append(f"- {row}: combined {_fmt(c)} {verb} both: best learned-only "
                   f"({_LABEL[learned]}) {_fmt(lv)} ({100 * (c / lv - 1):+.1f} %), best physics-only "
                   f"({_LABEL[physics]}) {_fmt(pv)} ({100 * (c / pv - 1):+.1f} %).")
    return out


def _rows(result: dict, table: dict, ref: str, columns, unit2: float = 1.0) -> list[str]:
    k = result["settings"]["n_modes"]
    cols = [_LABEL[c].replace("10 modes", f"{k} modes") for c in columns]
    lines = ["| observed | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for row, vals in table.items():
        best = min(vals[c][ref] for c in columns)
        cells = [_fmt(vals[c][ref] / unit2) for c in columns]
        cells = [f"**{x}**" if vals[c][ref] == best else x for c, x in zip(columns, cells, strict=True)]
        lines.append(f"| {row} | " + " | ".join(cells) + " |")
    return lines


def _realisations_md(oos: dict) -> list[str]:
    """Geometric-mean ratios (and wins) of the combined error over the best of each kind, across
    the held-out-action realisations."""
    ratios = oos["realisations"]
    n = len(next(iter(ratios.values()))["learned"])
    lines = [f"Over {n} realisations of this protocol (other seeds for the training and the test "
             "motions; each with its own training-data choice of the prior): the geometric mean of "
             "combined error / best learned-only error (10 modes or full cov., the better of the two in "
             "each realisation) and / best physics-only error (K⁻² or K⁻¹), with how often the combined "
             "model is better. Below 1: it beats them. \"combined\" weighs the residual variance per "
             "frame (`CombinedModel.mixture`); \"one σ²\" is the linear LLSE at the σ² of "
             "`CombinedModel.fit`.", "",
             "| observed | vs learned-only | vs physics-only | beats both | one σ²: vs learned-only | "
             "one σ²: vs physics-only |", "|---|---|---|---|---|---|"]

    def cell(v):
        v = np.asarray(v)
        return f"{np.exp(np.mean(np.log(v))):.2f} ({int((v < 1).sum())}/{len(v)})"

    for row, r in ratios.items():
        both = int(((np.asarray(r["learned"]) < 1) & (np.asarray(r["physics"]) < 1)).sum())
        fixed = [cell(r[k]) if k in r else "-" for k in ("learned_fixed", "physics_fixed")]
        lines.append(f"| {row} | {cell(r['learned'])} | {cell(r['physics'])} | {both}/{n} | {fixed[0]} | "
                     f"{fixed[1]} |")
    return lines


def _selection_text(sel: dict) -> str:
    other = {k: v for k, v in sel["by_kind"].items() if k != sel["kind"]}
    name = {"force": "K⁻²", "energy": "K⁻¹"}
    alt = "".join(f" (best {name[k]}: {v['log_likelihood']:.1f}, share {v['residual_share']:.3g}, "
                  f"τ² {v['noise_variance']:.3g} mm²)" for k, v in other.items())
    return (f"prior {name[sel['kind']]}, σ² = {sel['residual_share']:.3g} of the learned variance at the "
            f"markers, τ² = {sel['noise_variance']:.3g} mm²; held-out log-likelihood "
            f"{sel['log_likelihood']:.1f} nats/frame{alt}")


def _markdown(result: dict, suffix: str = "") -> str:
    s = result["settings"]
    u = result["mm_per_unit"]
    u2 = u * u
    oos = result["outside_span"]
    ours = {row: (v["modes"]["reach"] / u2, v["full"]["reach"] / u2) for row, v in result["table"].items()}
    thesis_rows = [f"| {row} | {a:.2e} | {b:.2e} | {ours[row][0]:.2e} | {ours[row][1]:.2e} |"
                   for row, (a, b) in THESIS_TABLE.items()]
    px = s.get("marker_noise_px", 0)
    noise = f"{s['marker_noise_mm']} mm" + (f", {px:g} px in both views (triangulated)" if px else "")
    out = [
        f"# Table 5.1 on synthetic ground truth: marker noise {noise}",
        "",
        f"Truth: `default_subject(seed={s['seed']}, resolution={s['truth_resolution']})` "
        f"({result['n_nodes_truth']} nodes: finer mesh, own stiffness, jaw hinge, lip contact, arch wrap); "
        f"preset `{s.get('preset', 'easy')}`"
        + (f", subject seed {result['subject_seed']} (own lip shape, dots at surface points)"
           if result.get("subject_seed") is not None else " (the model's rest shape, dots on its nodes)")
        + (", nonlinear tissue layer" if result.get("truth_physics") == "layer" else "") + ". "
        f"Model: `lip_mesh(0)` ({result['n_nodes_model']} nodes), default stiffness. "
        f"{s['n_frames']} frames of random gestures at 30 fps"
        + (" with head motion (known pose)" if s["head"] else "")
        + f"; marker noise {noise}. Train on frames 1-{s['n_train']} from the 16 markers "
        f"only (`Physics.reach` per frame, §4.1), test on the last {s['n_frames'] - s['n_train']}.",
        "",
        f"**Variance captured by {s['n_modes']} modes: {100 * result['variance_captured']:.4f} %** "
        "(thesis: 99.2 %).",
        "",
        "Error = mean squared error per hidden DOF (the DOFs neither observed nor anchored). "
        f"Units: mm², and the thesis's normalised units² with 1 unit = {u:.2f} mm (the default lips are "
        f"72 mm wide, the thesis's model 2.83 units wide, `lipgen.mesh.procedural.thesis_unit_mm`), so "
        f"units² = mm² / {u2:.1f}.",
        "",
        "## In the thesis's terms (reference: least-strain field of the 16 test markers), units²",
        "",
        "| observed | thesis 10 modes | thesis full cov. | ours 10 modes | ours full cov. |",
        "|---|---|---|---|---|",
        *thesis_rows,
        "",
        "Rows \"(all nodes)\" read the thesis's \"all points\" as every free node of the model; "
        "\"(16 points)\" as the 16 markers. All of them, mm²:",
        "",
        *_rows(result, result["table"], "reach", ("modes", "full", "physics_force", "combined")),
        "",
        "## Against the TRUE surface (the truth mesh at the model's nodes), mm²",
        "",
        f"\"combined\": {s['n_modes']} modes + a physical prior for the residual, its kind and noise "
        "variance τ² chosen from the training frames' markers only, by 5-fold (contiguous blocks) "
        "cross-validated marginal likelihood (`CombinedModel.fit`): "
        f"{_selection_text(result['selection'])}; the residual variance is then weighed per frame "
        "over a log-uniform grid by that frame's own observations (`CombinedModel.mixture`). "
        "\"combined (one σ²)\": the linear LLSE at the σ² of the cross-validation; \"combined (K⁻¹, "
        "one σ²)\": the same with the K⁻¹ prior imposed. The combined columns use their own τ² on the "
        "marker rows; the other estimators "
        f"are given the marker-noise variance ({result.get('noise_variance', s['marker_noise_mm'] ** 2):.3g} "
        "mm² "
        "per coordinate; through the rig, its mean over the training frames). The "
        "\"(all nodes)\" rows observe noise-free fields and use no noise variance.",
        "",
        *_rows(result, result["table"], "truth", COLUMNS),
        "",
        "Same, thesis units²:",
        "",
        *_rows(result, result["table"], "truth", COLUMNS, u2),
        "",
        f"Floor: the least-strain field of all 16 markers itself differs from the truth by "
        f"{result['reach_vs_truth_mse']:.3g} mm² per free DOF over all frames. Anchored DOFs are excluded: "
        f"the model holds its skin border still while the truth's chin rides on the jaw "
        f"({result['anchored_truth_mse']:.3g} mm² per anchored DOF on the test frames, the same for "
        "every estimator).",
        "",
        "## Outside the training span: the combined model (§6.1), mm² against the true surface",
        "",
        f"Trained without {', '.join(oos['held_out_test'])}; tested on {oos['n_test_frames']} frames that "
        f"use them (variance captured {100 * oos['variance_captured']:.3f} %). The combined model's "
        f"choice from its training frames: {_selection_text(oos['selection'])}.",
        "",
        *_rows(result, oos["table"], "truth", COLUMNS),
        "",
        *_verdict(oos["table"]),
        "",
        *_realisations_md(oos),
        "",
        "Test-set sensitivity of the one-σ² combined LLSE to the share σ² (not used for any choice; the "
        "kind and τ² as chosen), mm²:",
        "",
        "| observed | " + " | ".join(str(x) for x in SHARES) + " |",
        "|---" * (len(SHARES) + 1) + "|",
        *[f"| {row} | " + " | ".join(_fmt(v) for v in vals) + " |"
          for row, vals in oos["test_share_sweep"].items()],
        "",
        f"Pictures: `modes{suffix}.png` (mean and first modes), `error_vs_modes{suffix}.png` (error and "
        f"variance captured against the number of modes), `outside_span{suffix}.png`.",
        "",
    ]
    return "\n".join(out)


def _save(fig, path: Path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)


def _plot_modes(result: dict, path: Path, n_show: int = 4) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lipgen.mesh.plot import draw_mesh

    model, mesh = result["_model"], result["_mesh"]
    rest = mesh.vertices
    mean = model.mean_.reshape(-1, 3)
    n_show = min(n_show, len(model.components_))
    fig, axes = plt.subplots(n_show + 1, 4, figsize=(13, 3.0 * (n_show + 1)))
    for r in range(n_show + 1):
        if r == 0:
            shapes, titles = (rest, rest + mean), ("rest", "rest + mean")
        else:
            sd = 2 * np.sqrt(model.explained_variance_[r - 1])
            comp = model.components_[r - 1].reshape(-1, 3)
            shapes = (rest + mean - sd * comp, rest + mean + sd * comp)
            pct = 100 * model.explained_variance_ratio_[r - 1]
            titles = (f"mode {r} (-2σ, {pct:.1f} %)", f"mode {r} (+2σ)")
        for c, (view, k) in enumerate((("front", 0), ("front", 1), ("profile", 0), ("profile", 1))):
            ax = axes[r, c]
            draw_mesh(ax, mesh, view=view, vertices=shapes[k], markers=False, anchors=False, nose=False)
            ax.set_title(f"{titles[k]}, {view}", fontsize=9)
            ax.set_axis_off()
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def _plot_curves(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curve = result["modes_curve"]
    ks = curve["k"]
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.5))
    for ax, ref, title in ((axes[0], "reach", "vs least-strain field (thesis)"),
                           (axes[1], "truth", "vs true surface")):
        for row in result["table"]:
            ax.semilogy(ks, curve[row][ref], label=row)
        ax.axvline(result["settings"]["n_modes"], color="0.6", ls=":")
        ax.set_xlabel("number of modes")
        ax.set_ylabel("MSE per hidden DOF (mm²)")
        ax.set_title(title)
        ax.legend(fontsize=8)
    cum = np.asarray(result["cumulative_variance"])
    k = np.arange(1, len(cum) + 1)
    axes[2].semilogy(k, np.clip(1 - cum, 1e-12, None), "k.-")
    axes[2].set_xlabel("number of modes")
    axes[2].set_ylabel("variance not captured (fraction)")
    axes[2].set_title(f"{100 * result['variance_captured']:.4f} % captured by "
                      f"{result['settings']['n_modes']} modes")
    axes[2].set_xlim(0, min(len(cum), 60))
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def _plot_outside(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    oos = result["outside_span"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    rows = list(oos["table"])
    x = np.arange(len(rows))
    w = 0.8 / len(COLUMNS)
    for i, col in enumerate(COLUMNS):
        axes[0].bar(x + i * w, [oos["table"][r][col]["truth"] for r in rows], w, label=_LABEL[col])
    axes[0].set_xticks(x + 0.4 - w / 2, rows)
    axes[0].set_yscale("log")
    axes[0].set_ylabel("MSE vs true surface (mm²)")
    axes[0].set_title(f"held out of training: {', '.join(oos['held_out_test'])}")
    axes[0].legend(fontsize=8)
    for row, vals in oos["test_share_sweep"].items():
        axes[1].loglog(SHARES, vals, "o-", label=f"test {row}")
    axes[1].axvline(oos["selection"]["residual_share"], color="0.5", ls=":", label="chosen (training CV)")
    axes[1].set_xlabel("residual share")
    axes[1].set_ylabel("MSE (mm²)")
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def _suffix(noise_mm: float, n_runs: int) -> str:
    return f"_noise{noise_mm:g}" if n_runs > 1 else ""


def report_files(noise_mm) -> tuple[str, ...]:
    """The files :func:`write_report` writes for runs of marker noises ``noise_mm`` (one run each)."""
    noise_mm = list(noise_mm)
    pics = [f"{name}{_suffix(n, len(noise_mm))}.png" for n in noise_mm
            for name in ("modes", "error_vs_modes", "outside_span")]
    return ("report.md", "table51.json", *pics)


def write_report(results: dict | list[dict], out_dir: str | os.PathLike) -> Path:
    """Write ``report.md``, ``table51.json`` and the pictures of one or more runs to ``out_dir``.

    Several runs (e.g. different marker noise) become sections of one report; their pictures get
    a ``_noise<mm>`` suffix. Returns the report path.
    """
    runs = [results] if isinstance(results, dict) else list(results)
    if not runs:
        raise ValueError("write_report needs at least one result of run_table51")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out / "table51.json",
                      [{k: v for k, v in r.items() if not k.startswith("_")} for r in runs])
    sections = []
    for r in runs:
        suffix = _suffix(r["settings"]["marker_noise_mm"], len(runs))
        _plot_modes(r, out / f"modes{suffix}.png")
        _plot_curves(r, out / f"error_vs_modes{suffix}.png")
        _plot_outside(r, out / f"outside_span{suffix}.png")
        sections.append(_markdown(r, suffix))
    report = out / "report.md"
    atomic_write_bytes(report, "\n---\n\n".join(sections).encode())
    return report
