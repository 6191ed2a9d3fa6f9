"""The report of ``lipgen experiment nrsfm`` (``benchmarks.md``): the published figures, the tables
per sequence, the development bodies, the held-out motion-capture clips and the check of ``dai``'s
automatic K against the flat baseline."""

from __future__ import annotations

import numpy as np

__all__ = ["PUBLISHED", "SEEN_SEEDS", "ROUNDING", "worse_than_flat", "markdown"]

PUBLISHED = {
    "drink": [("Akhter et al. 2008, trajectory basis", 13, 0.025),
              ("Dai, Li & He 2012, block matrix method", 12, 0.027)],
    "jaws": [],
}
"""Published e3D figures per sequence: (source, K, e3D)."""

SEEN_SEEDS = frozenset({*range(100, 108), *range(300, 311), *range(400, 411), *range(700, 730),
                        *range(800, 820), *range(900, 906), *range(1000, 1020), *range(1100, 1120),
                        *range(1200, 1220), *range(1300, 1320)})
"""Validation-body seeds looked at while the rules were chosen (the automatic K: 100-107, 300-310;
the split-half shrinkage: 300-310, 400-410, 700-729, then checked once on 800-819; the consensus
depth: 300-307, 400, 405-407 and 900-903, 900-905 generated, then checked once on 1000-1019, which
were development bodies of issue 19's next pass, as 1100-1119 and 1200-1219 were of the passes
after; the depth-support test, :mod:`lipgen.nrsfm.support`, was chosen on 1000-1019, 1100-1119 and
1200-1219; 1300-1319 were its fresh check, then development bodies of the next pass): the check marks
them not fresh."""


ROUNDING = 1e-9
"""Relative margin above the flat baseline still counted as equal to it: the flat *answer* (the
tracks with zero depth, as the depth-support test returns it) is computed on another path than the
baseline and came out 1.5e-12 above it on human-dance-1410."""


def worse_than_flat(e3d: float, flat: float) -> bool:
    """``e3d`` worse than the flat baseline's ``flat`` by more than rounding (:data:`ROUNDING`)."""
    return e3d > flat * (1.0 + ROUNDING)


def _ranges(seeds: list[int]) -> str:
    """``[1, 2, 3, 7]`` as ``"1-3, 7"``."""
    parts, start = [], None
    for i, s in enumerate(seeds):
        if start is None:
            start = s
        if i + 1 == len(seeds) or seeds[i + 1] != s + 1:
            parts.append(str(start) if start == s else f"{start}-{s}")
            start = None
    return ", ".join(parts)


def _halves(c: dict) -> str:
    """The check table's cell of the depth-support test: the halves' disagreement, and flat when dropped."""
    angle = c.get("support_angle")
    if angle is None or angle != angle:       # not run (an older record) or not tested (NaN)
        return "-"
    if c.get("depth_supported", True):
        return f"{angle:.2f}"
    return f"{angle:.1f}: flat ({c['e3d_unsupported']:.3f})"


def _runs_table(entries: list[dict], settings) -> list[str]:
    """Markdown lines: one row per sequence, each method at each K (e3D and CPU), then the runs worse
    than flat."""
    ks = [*map(str, settings.validation_ks), "auto"]
    runs = " | ".join(f"{m} K={k}" for m in settings.methods for k in ks)
    lines = [f"| sequence | frames | P | deg/frame | flat | {runs} |",
             "|---" * (5 + len(settings.methods) * len(ks)) + "|"]
    for entry in entries:
        cells = [f"{r['e3d']:.3f} ({r['cpu_seconds']:.1f})" + (f" K={r['k']}" if r["auto"] else "")
                 for r in entry["runs"]]
        lines.append(f"| {entry['name']} | {entry['frames']} | {entry['points']} | "
                     f"{entry['degrees_per_frame']:.1f} | {entry['flat_e3d']:.3f} | {' | '.join(cells)} |")
    worse = [(e["name"], r["method"], r["k"]) for e in entries for r in e["runs"]
             if worse_than_flat(r["e3d"], e["flat_e3d"])]
    listed = ", ".join(f"{n} {m} K={k}" for n, m, k in worse) if worse else "none"
    return [*lines, "", f"Runs worse than the flat baseline: {listed}.", ""]


def markdown(result: dict, settings) -> str:
    """``benchmarks.md`` of :func:`lipgen.experiments.nrsfm_benchmarks.run_nrsfm_benchmarks`.

    Parameters
    ----------
    result : dict
        The figures that function returns.
    settings : NrsfmBenchSettings
        What was run (methods, validation Ks and frames).

    Returns
    -------
    str
    """
    lines = ["# Non-rigid SfM on the standard sequences", "",
             "e3D as defined in `shared/benchmarks/nrsfm/README.md` (normalised by s, rows centred, one "
             "orthogonal 3x3 with reflection over all frames, mean per-frame mean point distance). "
             "Times are CPU and wall-clock seconds, one BLAS thread, on a shared 2-core machine "
             f"(load average {result['load_before'][0]:.1f} before, {result['load_after'][0]:.1f} after); "
             "compare them as ratios. *auto* marks the K the method chooses itself: for `dai` and `dai-ba` "
             "the K with the smoothest rotations (among them the smallest fitted exactly by K shapes) "
             "(`lipgen.nrsfm.kchoice`; its time is that of `reconstruct(W, \"auto\")`: the rotations at "
             "every K it tries, the shapes only at the Ks the choice needs (`lipgen.nrsfm.kscan`), plus "
             "`dai-ba`'s "
             "refinement at the chosen K); `dai`'s depth is then the mean of the 4 smoothest Ks' depths, "
             "shrunk by the James-Stein factor of their spread (`lipgen.nrsfm.consensus`), or zero (the "
             "flat answer) when the even and the odd frames alone give rotations that disagree "
             "(`lipgen.nrsfm.support`); for `bregler` "
             "the reprojection-curve rule. `em-ppca` counts K as deformation modes beyond the mean "
             "shape, so it has "
             "K + 1 basis shapes (column *shapes*): em-ppca K = 12 is the same model size as dai K = 13.",
             ""]
    for name, seq in result["sequences"].items():
        lines += [f"## {name} ({seq['frames']} frames x {seq['points']} points)", ""]
        pub = PUBLISHED.get(name, [])
        if pub:
            lines += ["Published: " + "; ".join(f"{src}: **{e:.3f}** (K = {k})" for src, k, e in pub), ""]
        else:
            lines += ["No published e3D is given for this file in the benchmark README, and we found no "
                      "citable one: the tables of Akhter et al. 2008/2011, Dai et al. 2012/2014 and "
                      "Gotardo & Martinez 2011, which report on Torresani's shark, were not available to "
                      "us in readable form, so no published figure is claimed here.", ""]
        lines += [f"Flat baseline (the tracks with zero depth): **{seq['flat_e3d']:.4f}**.", "",
                  "| method | K | shapes | e3D | RMS reprojection (% of tracks) | CPU (s) | wall (s) |",
                  "|---|---|---|---|---|---|---|"]
        for r in seq["runs"]:
            k = f"{r['k']} (auto)" if r["auto"] else str(r["k"])
            lines.append(f"| {r.get('label', r['method'])} | {k} | {r['n_basis']} | {r['e3d']:.4f} | "
                         f"{100 * r['relative_reprojection']:.3g} "
                         f"| {r.get('cpu_seconds', float('nan')):.2f} | {r['seconds']:.2f} |")
        for r in seq["runs"]:
            if r["method"] == "dai" and r["auto"] and "depth_supported" in r:
                angle = r["support_angle"]
                verdict = ("kept" if r["depth_supported"] else
                           f"dropped, the flat answer (else {r['e3d_unsupported']:.4f})")
                lines += ["", f"`dai` K = auto: depth {verdict}"
                          + (f"; the even and the odd frames' rotations disagree by {angle:.3g} degrees "
                             "(median; `lipgen.nrsfm.support`)" if angle == angle else
                             " (not tested: an exact K-shape fit, or too few frames)") + "."]
        c = seq["curve"]
        lines += ["", f"Reprojection curve (`dai`, `{name}_curve.png`): K = {c['ks'][0]}..{c['ks'][-1]}, "
                  "relative RMS " + ", ".join(f"{100 * v:.3g}%" for v in c["relative"])
                  + f". Rule: {c['rule']}; chosen K = {c['chosen']}.", ""]
    if result.get("missing"):
        base = result["missing"][0]["cpu_seconds"]
        lines += ["## Missing points: drink, `dai` K = 12", "",
                  "Points hidden at random or in gaps of 20-60 frames of one point "
                  "(`hide_points`, seed 0); the hidden entries are filled by the rank-3K model and the "
                  "point's track interpolated in time (`lipgen.nrsfm.completion`).", "",
                  "| hidden | fraction | e3D | CPU (s) | CPU / complete |", "|---|---|---|---|---|"]
        lines += [f"| {r['hidden']} | {r['fraction']:.3f} | {r['e3d']:.4f} | {r['cpu_seconds']:.2f} | "
                  f"{r['cpu_seconds'] / base:.2f} |" for r in result["missing"]]
        lines += [""]
    if result["validation"]:
        lines += ["## Development bodies: synthetic human bodies (`lipgen.nrsfm.validation`)", "",
                  f"{settings.validation_frames} frames each, orthographic, no noise; no method's code was "
                  "fitted to them, but they are not held out (see the last sentence). e3D (CPU seconds); "
                  "K counts basis shapes (em-ppca: K - 1 modes + the mean); "
                  "*auto*: the method's own K (`dai`, `dai-ba`: the smoothest rotations; the others: the "
                  "reprojection curve). These seeds were used to choose the automatic-K rule.", "",
                  *_runs_table(result["validation"], settings)]
    if result.get("mocap"):
        from lipgen.nrsfm.mocap import CLIPS, SEEDS, STEP

        entries = result["mocap"]
        clips = settings.mocap_clips or tuple(CLIPS)
        seeds = " and ".join(f"{s} + i" for s in SEEDS)
        lines += ["## Held out: public motion capture (CMU clips, `lipgen.nrsfm.mocap`)", "",
                  "Other clips of the CMU library than the standard sequences' ("
                  f"{', '.join(f'{c}: {CLIPS[c][1]}' for c in clips)}), never used to choose any rule: the "
                  f"skeleton's joints and end sites ({entries[0]['points']} points), one frame in {STEP}, "
                  f"each filmed {len(SEEDS)} times orthographically as the bodies above (seeds {seeds} for "
                  f"clip i of `CLIPS`). Columns as above.", "",
                  *_runs_table(entries, settings)]
        auto = [(e, r) for e in entries for r in e["runs"] if r["method"] == "dai" and r["auto"]]
        if auto:
            worse = [e["name"] for e, r in auto if worse_than_flat(r["e3d"], e["flat_e3d"])]
            lines += [f"`dai` K = auto (the default): worse than flat on {len(worse)} of {len(auto)}"
                      + (f" ({', '.join(worse)})" if worse else "") + f"; mean e3D "
                      f"{np.mean([r['e3d'] for _, r in auto]):.3f} against flat "
                      f"{np.mean([e['flat_e3d'] for e, _ in auto]):.3f}.", ""]
    if result.get("check"):
        worse = [c["name"] for c in result["check"] if worse_than_flat(c["e3d"], c["flat_e3d"])]
        worse_single = [c["name"] for c in result["check"] if worse_than_flat(c["e3d_single"], c["flat_e3d"])]
        seen = sorted({c["seed"] for c in result["check"] if c["seed"] in SEEN_SEEDS})
        lines += ["## Check: `dai` with K = auto beside the flat baseline", "",
                  "Seeds run while the rules were chosen (the automatic K, the split-half depth shrinkage, "
                  f"the consensus depth): {_ranges(sorted(SEEN_SEEDS))}; of the seeds below, "
                  + (f"{', '.join(map(str, seen))} were among them" if seen else "none was")
                  + " (column *fresh*). *dai K=auto*: the default, the consensus depth of the smoothest Ks "
                  "(`lipgen.nrsfm.consensus`) shrunk by the James-Stein *factor*, or the flat answer when "
                  "the even and the odd frames' rotations disagree by more than the test's limit "
                  "(`lipgen.nrsfm.support`; column *halves*: their median disagreement in degrees, *flat* "
                  "where the depth was dropped, with the consensus answer's e3D in brackets); *single K*: "
                  "the chosen K's own depth.", "",
                  "| sequence | fresh | flat | dai K=auto | K | factor | halves (deg) | single K | CPU (s) |",
                  "|---|---|---|---|---|---|---|---|---|"]
        lines += [f"| {c['name']} | {'no' if c['seed'] in SEEN_SEEDS else 'yes'} | {c['flat_e3d']:.3f} | "
                  f"{c['e3d']:.3f} | {c['k']} | {c['consensus_factor']:.3f} | {_halves(c)} | "
                  f"{c['e3d_single']:.3f} | {c['cpu_seconds']:.1f} |" for c in result["check"]]
        dropped = [c for c in result["check"] if not c.get("depth_supported", True)]
        lines += ["", f"Worse than the flat baseline: {len(worse)} of {len(result['check'])}"
                  + (f" ({', '.join(worse)})" if worse else "")
                  + f"; with the chosen K's own depth {len(worse_single)}. Depth dropped (flat answer): "
                  f"{len(dropped)}"
                  + (f" ({', '.join(c['name'] for c in dropped)})" if dropped else "") + ".",
                  ""]
    if any(r.get("label", r["method"]) != r["method"] for seq in result["sequences"].values()
           for r in seq["runs"]):
        lines += ["Rows labelled `(em_iter=N)` rerun em-ppca with N EM iterations instead of the default "
                  "cap: EM creeps, and its e3D keeps improving well past the default.", ""]
    return "\n".join(lines)
