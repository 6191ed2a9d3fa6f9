"""Table 5.1 with honest splits: another utterance, another subject, over several subject seeds.

:func:`run_table51` tests on the last 10 frames of the clip it trained on; one seed then swings
the figures by an order of magnitude. :func:`run_splits` measures instead, for each seed ``s``
of ``seeds`` (subject seed and motion seed ``s``):

- **train**: ``n_train`` frames of subject ``s`` (the preset's motion), 10 modes and the combined
  model learned from their least-strain fields (as :func:`~lipgen.experiments.table51.run_table51`);
- **utterance split**: ``n_test`` consecutive frames of another utterance of the same subject
  (another motion seed; frames ``lead_in`` to ``lead_in + n_test``, away from the rest pose);
- **subject split**: the same frames from another subject (subject seed ``s + 1000``, its own
  shape, dots, stiffness and motion seed).

Each cell is the error per hidden DOF (:mod:`lipgen.evaluate.metric`) against the true surface
and against the least-strain field, and the true-surface error relative to the test motion's
own mean square. Over the seeds: the mean and a 95 % Student-t interval
(:func:`mean_interval`). The figure :func:`order` reports the thesis's qualitative finding
(x-y worse than y-z from 16 points with learned modes) per seed.

The estimators are also compared **paired**: every estimator is scored on the same seeds and test
frames, so the seed-to-seed spread (some subjects and utterances are harder for every method)
cancels in the per-seed ratio of two estimators' errors. :func:`paired_interval` gives the
geometric mean of that ratio over the seeds and its 95 % t-interval (a paired t-test on the
log errors); a pair is told apart when the interval excludes 1.

Each test window also records its own x-y / y-z order and its depth-over-lateral motion (the
variance of the true marker displacements in z over that in x); :func:`window_orders` relates the
two. ``marker_noise_px`` measures the markers through the camera-mirror rig
(:func:`~lipgen.experiments.table51_protocol.measure_through_rig`): pixel noise in both views,
triangulated, so depth is measured worst, as in the thesis's data.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass

import numpy as np

from lipgen.experiments.table51_protocol import (
    Table51Settings,
    _motion,
    _score,
    fit_combined,
    make_subject,
    observation_rows,
    observe,
)
from lipgen.experiments.table51_stats import (
    ESTIMATORS,
    SPLITS,
    _mean_tables,
    _pairs,
    aggregate,
    mean_interval,
    order,
    paired_interval,
)

__all__ = ["SplitSettings", "run_splits", "write_splits_report", "mean_interval", "paired_interval", "order",
           "window_orders", "aggregate", "split_section_lines", "ESTIMATORS", "SPLITS"]

log = logging.getLogger(__name__)

@dataclass(frozen=True)
class SplitSettings:
    """Settings of :func:`run_splits` (the defaults: 5 subject seeds, the ``default`` preset)."""

    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    preset: str = "default"
    n_train: int = 140
    n_test: int = 10
    lead_in: int = 30
    n_windows: int = 3
    """Test windows per split and seed, each ``n_test`` consecutive frames of its own utterance;
    a seed's figure is their mean."""
    n_modes: int = 10
    marker_noise_mm: float = 0.0
    marker_noise_px: float = 0.0
    """Pixel noise in both views of the rig, triangulated (``Table51Settings.marker_noise_px``)."""
    head: bool = True
    truth_resolution: int = 1

    def __post_init__(self) -> None:
        if len(self.seeds) < 2 or len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"seeds must hold 2 or more distinct subject seeds (5 for the report), got "
                             f"{self.seeds}")
        if self.n_test < 10:
            raise ValueError(f"n_test must be >= 10 consecutive test frames (thesis Table 5.1), got "
                             f"{self.n_test}")
        if not 1 <= self.n_modes < self.n_train:
            raise ValueError(f"need 1 <= n_modes < n_train, got {self.n_modes}, {self.n_train}")
        if self.n_windows < 1:
            raise ValueError(f"n_windows must be >= 1, got {self.n_windows}")
        if self.lead_in < 0:
            raise ValueError(f"lead_in must be >= 0 frames, got {self.lead_in}")
        Table51Settings(preset=self.preset, marker_noise_mm=self.marker_noise_mm,
                        marker_noise_px=self.marker_noise_px)  # checks the rest


def _settings(s: SplitSettings, subject_seed: int) -> Table51Settings:
    own = s.preset != "easy"
    return Table51Settings(seed=subject_seed, preset=s.preset, subject_seed=subject_seed if own else None,
                           marker_noise_mm=s.marker_noise_mm, marker_noise_px=s.marker_noise_px, head=s.head,
                           truth_resolution=s.truth_resolution, n_modes=s.n_modes)


def _clip(s: SplitSettings, t51: Table51Settings, subject, physics, n: int, motion_seed: int, rng):
    from lipgen.subject.motion import head_motion

    acts, residual = _motion(t51, subject, n, motion_seed)
    head = head_motion(n, motion_seed) if s.head else None
    return observe(subject, physics, acts, head, s.marker_noise_mm, rng, residual, s.marker_noise_px)


def _window(data, start: int, n: int):
    from lipgen.experiments.table51_protocol import Observed

    return Observed(*(a[start:start + n] for a in (data.goals, data.reach, data.truth, data.activations)))


def run_splits(settings: SplitSettings | None = None) -> dict:
    """Every seed's tables and the mean and 95 % interval of each cell (JSON-ready)."""
    from lipgen.fem import Physics, dofs
    from lipgen.mesh.procedural import lip_mesh, thesis_unit_mm
    from lipgen.modes.model import ModeModel

    s = settings or SplitSettings()
    mesh = lip_mesh(0)
    physics = Physics(mesh)
    rows = {k: v for k, v in observation_rows(mesh).items() if "points" in k}
    per_seed = []
    for seed in s.seeds:
        log.info("splits: subject seed %d", seed)
        rng = np.random.default_rng(seed)
        t51 = _settings(s, seed)
        subject = make_subject(t51)
        train = _clip(s, t51, subject, physics, s.n_train, 1000 * seed, rng)
        # the estimators are given the measurement-noise variance (per coordinate, mm²)
        noise_var = s.marker_noise_mm**2 if s.marker_noise_px == 0 else float(np.mean(train.error**2))
        model = ModeModel(s.n_modes).fit(train.reach, mesh=mesh)
        combined = fit_combined(model, physics, train.reach)
        n = s.lead_in + s.n_test
        at_markers = {row: (rows[f"{row} (16 points)"], model.llse(rows[f"{row} (16 points)"], s.n_modes,
                                                                   noise=noise_var), dofs(mesh.markers, hid))
                      for row, hid in (("xy", "z"), ("yz", "x"))}
        other = _settings(s, seed + 1000)
        tests = {"utterance": (t51, subject), "subject": (other, make_subject(other))}
        record = {"seed": seed, "variance_captured": float(np.sum(model.explained_variance_ratio_)),
                  "test_mean_square_mm2": {}, "noise_variance_mm2": noise_var, "windows": {}}
        for k, (split, (ts, sub)) in enumerate(tests.items()):
            tables, ms, wins = [], [], []
            for w in range(s.n_windows):
                data = _window(_clip(s, ts, sub, physics, n, 1000 * seed + 10 * (k + 1) + w, rng), s.lead_in,
                               s.n_test)
                tables.append(_score(model, physics, data, rows, noise_var, combined, ESTIMATORS))
                ms.append(float(np.mean(data.truth**2)))
                wins.append(_window_figures(tables[-1], data.truth[:, mesh.markers]))
                wins[-1]["order_markers"] = _marker_order(at_markers, data.reach)
            record["windows"][split] = wins
            record.setdefault("order_markers", {})[split] = float(np.mean([w["order_markers"] for w in wins]))
            record[split] = _mean_tables(tables)
            record["test_mean_square_mm2"][split] = float(np.mean(ms))
        per_seed.append(record)
    result = {"settings": asdict(s), "mm_per_unit": thesis_unit_mm(mesh), "per_seed": per_seed,
              **aggregate(per_seed, list(rows))}
    for split in SPLITS:
        result["order_xy_over_yz"][split]["markers"] = mean_interval([r["order_markers"][split]
                                                                      for r in per_seed])
    return result


def _marker_order(at_markers: dict, fields) -> float:
    """x-y over y-z with 10 modes scored only where the thesis had data: the hidden coordinates of
    the 16 markers (z for the x-y row, x for the y-z row) against the measured markers (the
    least-strain field ``fields`` (F, n, 3) reaches them exactly)."""
    F = len(fields)
    U = np.asarray(fields).reshape(F, -1)
    err = {row: float(np.mean((est(U[:, d]).reshape(F, -1)[:, hid] - U[:, hid]) ** 2))
           for row, (d, est, hid) in at_markers.items()}
    return err["xy"] / err["yz"]


def _window_figures(table: dict, markers) -> dict:
    """One test window's x-y / y-z order and its depth-over-lateral motion: the summed variance
    over the window's frames of the true marker displacements (F, 16, 3) in z over that in x."""
    var = np.var(np.asarray(markers), axis=0).sum(axis=0)
    return {"order_truth": order(table, "truth"), "order_reach": order(table, "reach"),
            "z_over_x": float(var[2] / var[0])}


def window_orders(result: dict, split: str) -> dict:
    """Each test window's x-y / y-z order against its depth-over-lateral motion.

    Parameters
    ----------
    result : dict
        :func:`run_splits`'s result.
    split : str
        One of :data:`SPLITS`.

    Returns
    -------
    dict
        ``"n"``: windows; ``"above_1"``: {ref: windows with the thesis's order}; ``"spearman"``:
        {ref: rank correlation of the order with ``z_over_x``}; ``"top_quartile"``: {ref: median
        order of the quarter of windows with the most depth motion}; refs ``"truth"``, ``"reach"``.
    """
    from scipy import stats

    wins = [w for r in result["per_seed"] for w in r.get("windows", {}).get(split, [])]
    if len(wins) < 4:
        raise ValueError(f"need 4 or more test windows with their figures, got {len(wins)}")
    z = np.array([w["z_over_x"] for w in wins])
    top = z >= np.quantile(z, 0.75)
    out = {"n": len(wins), "above_1": {}, "spearman": {}, "top_quartile": {}}
    for ref in ("truth", "reach"):
        o = np.array([w[f"order_{ref}"] for w in wins])
        out["above_1"][ref] = int(np.sum(o > 1))
        out["spearman"][ref] = float(stats.spearmanr(o, z).statistic)
        out["top_quartile"][ref] = float(np.median(o[top]))
    return out


def _window_lines(result: dict, split: str) -> list[str]:
    try:
        w = window_orders(result, split)
    except ValueError:
        return []
    return [f"Per test window ({w['n']}): x-y over y-z is above 1 in {w['above_1']['truth']} vs the true "
            f"surface and {w['above_1']['reach']} vs the least-strain field; its rank correlation with the "
            f"window's depth-over-lateral marker motion (z over x variance) is {w['spearman']['truth']:.2f} "
            f"and {w['spearman']['reach']:.2f}; in the quarter of windows with the most depth motion its "
            f"median is {w['top_quartile']['truth']:.2f} and {w['top_quartile']['reach']:.2f}.", ""]


_NAMES = {"modes": "10 modes", "full": "full cov.", "combined": "combined",
          "physics_force": "physics (reach)"}


def _cell(v) -> str:
    return f"{v[0]:.3g} [{v[1]:.3g}, {v[2]:.3g}]"


def split_section_lines(result: dict, split: str) -> list[str]:
    """The markdown lines of one split's section of a report: the table of means and intervals,
    the paired comparison, the x-y / y-z order and the thesis's figures beside.

    Parameters
    ----------
    result : dict
        :func:`run_splits`' result (or one with the same ``"summary"``, ``"paired"``,
        ``"distinguished"``, ``"separated"``, ``"order_xy_over_yz"`` and ``"mm_per_unit"``).
    split : str
        One of :data:`SPLITS`.
    """
    from lipgen.experiments.table51_report import THESIS_TABLE

    u2 = result["mm_per_unit"] ** 2
    lines = [f"## {split.capitalize()} split: vs the true surface, mm² (relative)", "",
             "| observed | " + " | ".join(_NAMES[c] for c in ESTIMATORS) + " | intervals separate |",
             "|---|" + "---|" * (len(ESTIMATORS) + 1)]
    for row, cols in result["summary"][split].items():
        cells = [f"{_cell(cols[c]['truth'])} ({cols[c]['truth_relative'][0]:.3f})" for c in ESTIMATORS]
        sep = result["separated"][split]
        lines.append(f"| {row} | " + " | ".join(cells) + f" | {'yes' if sep['truth'][row] else 'no'} "
                     f"(relative: {'yes' if sep['truth_relative'][row] else 'no'}) |")
    lines += ["", "Paired (the same seeds and frames): geometric mean over the seeds of the ratio of two "
              "estimators' errors vs the true surface, and its 95 % interval; **bold** where it "
              "excludes 1.", "",
              "| observed | " + " | ".join(f"{_NAMES[a]} / {_NAMES[b]}" for a, b in _pairs())
              + " | told apart |", "|---|" + "---|" * (len(_pairs()) + 1)]
    for row, pairs in result["paired"][split].items():
        cells = [(f"**{_cell(v)}**" if not v[1] <= 1.0 <= v[2] else _cell(v)) for v in pairs.values()]
        lines.append(f"| {row} | " + " | ".join(cells)
                     + f" | {'yes' if result['distinguished'][split][row] else 'no'} |")
    o = result["order_xy_over_yz"][split]
    mk = (f", {_cell(o['markers'])} at the hidden marker coordinates vs the measured markers"
          if "markers" in o else "")
    lines += ["", f"x-y over y-z (16 points, 10 modes): {_cell(o['truth'])} vs the true surface, "
              f"{_cell(o['reach'])} vs the least-strain field{mk} (thesis: "
              f"{THESIS_TABLE['xy (16 points)'][0] / THESIS_TABLE['yz (16 points)'][0]:.1f}).", "",
              *_window_lines(result, split),
              "In the thesis's terms (vs the least-strain field, units², 10 modes / full cov.):", "",
              "| observed | thesis | ours |", "|---|---|---|"]
    for row, (a, b) in THESIS_TABLE.items():
        c = result["summary"][split][row]
        lines.append(f"| {row} | {a:.2e} / {b:.2e} | {c['modes']['reach'][0] / u2:.2e} / "
                     f"{c['full']['reach'][0] / u2:.2e} |")
    lines.append("")
    return lines


def write_splits_report(result: dict, out) -> str:
    """Write ``splits.md`` and ``splits.json`` into the folder ``out``; returns the markdown path."""
    import json
    from pathlib import Path

    from lipgen.evaluate.metric import ERROR_DEFINITION

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    s = result["settings"]
    v = result["variance_captured"]
    lines = ["# Table 5.1 with utterance and subject splits", "",
             f"Preset `{s['preset']}`, subject seeds {list(s['seeds'])}; trained on {s['n_train']} "
             f"frames of one utterance; tested on {s['n_windows']} windows of {s['n_test']} consecutive "
             f"frames of other utterances (frames {s['lead_in']}-{s['lead_in'] + s['n_test'] - 1}) of the "
             f"same subject and of another subject (seed + 1000); marker noise {s['marker_noise_mm']} mm"
             f" (world) and {s.get('marker_noise_px', 0.0)} px (in both views of the rig, triangulated).",
             "",
             f"Error: {ERROR_DEFINITION}. Mean over the seeds and 95 % Student-t interval.", "",
             f"10 modes hold {100 * v[0]:.2f} % [{100 * v[1]:.2f}, {100 * v[2]:.2f}] of the training "
             "variance (thesis: 99.2 %).", ""]
    for split in SPLITS:
        lines += split_section_lines(result, split)
    md = out / "splits.md"
    md.write_text("\n".join(lines) + "\n")
    (out / "splits.json").write_text(json.dumps(result, indent=1))
    return str(md)
