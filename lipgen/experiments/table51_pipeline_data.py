"""Data of :mod:`lipgen.experiments.table51_pipeline`: datasets made and reconstructed once, the
frames of reference and rests of the recordings, and the marker displacement error."""

from __future__ import annotations

from pathlib import Path

__all__ = ["make_dataset", "reconstruct", "normalised", "marker_error", "model_line", "order_lines",
           "reference_line", "beside_lines"]


def make_dataset(path: Path, gs, workers: int, progress: bool):
    """The dataset at ``path`` made with settings ``gs`` (generated, or resumed, when incomplete)."""
    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import Dataset

    started = (path / "manifest.json").is_file()
    if not started or Dataset(path).missing(truth=True):
        generate(path, gs, workers=workers, resume=started, progress=progress)
    return Dataset(path)


def reconstruct(path: Path, progress: bool):
    """The reconstruction of the dataset at ``path``, cached as ``path.recon.npz``."""
    from lipgen.recon.pipeline import Reconstruction, reconstruct_dataset

    file = path.with_suffix(".recon.npz")
    if file.is_file():
        return Reconstruction.load(file)
    from lipgen.dataset.layout import Dataset

    # as reconstructed before the rest choice: normalised() measures from the rest its settings name
    recon = reconstruct_dataset(path, progress=progress, reference_frames=range(len(Dataset(path))),
                                rest="model")
    recon.save(file)
    return recon


def normalised(s, recons: dict, physics) -> tuple[dict, dict]:
    """The reconstructions in the frame of reference of ``s`` and the rest (P, 3) of each (None:
    the model's).

    ``rest="training"`` re-normalises at scale 1 and measures the training and the utterance
    recordings from the training recording's rest (:func:`lipgen.recon.rest.recording_rest`), the
    other subject from the model's rest; ``"own"`` likewise, but the other subject (and the
    utterance with ``utterance_reference="own"``) from its own recording's rest, estimated on all
    of its frames (its test windows included: every marker of the frames nearest the model's rest
    shapes it); ``"metric"`` at scale 1 from the model's rest; ``"model"`` as reconstructed. The
    utterance is re-normalised with the training reference if ``utterance_reference="train"``.
    """
    from lipgen.recon.rereference import renormalize
    from lipgen.recon.rest import metric_renormalize

    out = dict(recons)
    M = physics.mesh.vertices[physics.mesh.markers]
    ref = recons["train"] if s.utterance_reference == "train" else None
    if s.rest == "model":
        if s.utterance_reference == "train":
            out["utterance"] = renormalize(recons["utterance"], recons["train"], physics)
        return out, dict.fromkeys(recons)
    if s.rest == "metric":
        out["train"], _ = metric_renormalize(recons["train"], physics, rest=M)
        out["utterance"], _ = metric_renormalize(recons["utterance"], physics, rest=M, reference=ref)
        out["subject"], _ = metric_renormalize(recons["subject"], physics, rest=M)
        return out, dict.fromkeys(recons)
    out["train"], rest = metric_renormalize(recons["train"], physics)
    rests = {"train": rest}
    if s.rest == "own" and ref is None:
        out["utterance"], rests["utterance"] = metric_renormalize(recons["utterance"], physics)
    else:
        out["utterance"], rests["utterance"] = metric_renormalize(recons["utterance"], physics, rest=rest,
                                                                  reference=ref)
    if s.rest == "own":
        out["subject"], rests["subject"] = metric_renormalize(recons["subject"], physics)
    else:  # another subject has no training recording: the model's rest
        out["subject"], _ = metric_renormalize(recons["subject"], physics, rest=M)
        rests["subject"] = None
    return out, rests


def marker_error(recon, ds, mesh, rest=None) -> dict:
    """RMS error (mm) of the reconstructed marker displacements (normalised markers minus ``rest``,
    default the model's rest) against the true ones (model-frame marks minus the subject's rest) over the
    accepted sightings; ``"after_offset"``: once each marker's mean error over the frames (a
    constant offset, e.g. from the normalisation's reference frame) is taken out."""
    from lipgen.evaluate.displacement import displacement_error
    from lipgen.evaluate.scoring import load_truth

    P = len(mesh.markers)
    rest = mesh.vertices[mesh.markers] if rest is None else rest
    d = displacement_error(recon.markers, recon.visible, rest, load_truth(ds)["marks_model"][:, :P],
                           ds.rest_marks()[:P])
    return {"rms": d["rms_mm"], "after_offset": d["after_offset_rms_mm"]}


def model_line(s: dict) -> str:
    """The report's sentence on the rest, the learning and the noise term (settings ``s``)."""
    rest = {"training": "Displacements are measured from the subject's rest estimated on the training "
                        "recording (each marker's median over its accepted sightings in the frames nearest "
                        "the model's rest), at the rig's metric scale, for the training and the utterance "
                        "recordings; the other subject (no training recording) from the model's rest "
                        "markers at metric scale (`lipgen.recon.rest`)",
            "own": "Displacements are measured from the subject's rest estimated on the training "
                   "recording (each marker's median over its accepted sightings in the frames nearest "
                   "the model's rest), at the rig's metric scale; the other subject from its own "
                   "recording's rest, estimated alike on all its frames, its test frames included "
                   "(`lipgen.recon.rest`)",
            "metric": "Displacements are measured from the model's rest markers at the rig's metric scale "
                      "(scale 1, not a similarity fitted on a speaking frame; `lipgen.recon.rest`)",
            }.get(s.get("rest", "model"), "Displacements are measured from the model's rest markers, at the "
                                          "scale of a similarity fitted on the reference frame")
    learn = ("the learned estimators learn the marker DOFs from the measured entries only (EM; a marker "
             "never measured in training is not used by them)" if s.get("learning", "all") == "measured"
             else "the learned estimators learn from the fields as they are (fills included)")
    noise = {"measured": "their LLSE has the training recording's second-difference marker noise as its "
                         "noise term",
             "robust": "their LLSE has the training recording's second-difference marker noise plus extra "
                       "noise of unknown size weighed by each frame's own observations (a scale mixture)",
             }.get(s.get("noise", "none"), "their LLSE has no noise term")
    return f"{rest}; {learn}; {noise}."


def order_lines(result: dict) -> list[str]:
    """The x-y / y-z order (10 modes) against each reference, and which one the thesis's is."""
    from lipgen.experiments.table51_report import THESIS_TABLE
    from lipgen.experiments.table51_stats import SPLITS

    thesis = THESIS_TABLE["xy (16 points)"][0] / THESIS_TABLE["yz (16 points)"][0]
    refs = [("truth", "true surface"), ("reach", "least-strain field (measured)"),
            ("markers", "measured markers")]
    refs = [(k, name) for k, name in refs if all(k in result["order_xy_over_yz"][sp] for sp in SPLITS)]
    lines = ["## The thesis's x-y / y-z order (10 modes, 16 points)", "",
             "The error of the x-y row over that of the y-z row (> 1: x-y is worse, the thesis's order; "
             f"thesis {thesis:.1f}), mean over the seeds of each seed's ratio and its 95 % interval.", "",
             "| split | " + " | ".join(f"vs the {name}" for _, name in refs) + " |",
             "|---|" + "---|" * len(refs)]
    for split in SPLITS:
        o = result["order_xy_over_yz"][split]
        lines.append(f"| {split} | " + " | ".join(
            f"{o[k][0]:.3g} [{o[k][1]:.3g}, {o[k][2]:.3g}]" for k, _ in refs) + " |")
    lines += ["", "The thesis had no true surface: its reference was its own measured data (the least-strain "
              "fields of its tracked, reconstructed markers). Its finding, and the issue's \"x-y is worse "
              "than y-z\", refer to that kind of reference: the columns 'least-strain field (measured)' "
              "(all hidden DOFs of the frame's reconstructed field) and 'measured markers' (only the "
              "hidden coordinates of the markers the frame measured: z in the x-y row, x in the y-z "
              "row). The true-surface column says what the subject actually did; it is reported beside, "
              "not instead.", ""]
    return lines


def reference_line(which: str) -> str:
    """The report's sentence on the normalisation references of the test recordings."""
    utt = ("the training recording's (re-normalised with it: one subject, one frame of reference)"
           if which == "train" else "its own most neutral frame's")
    return ("Normalisation reference: the training recording's own most neutral frame; the utterance "
            f"split's test recording: {utt}; the subject split's: its own (another subject has another "
            "rest shape and size).")


def beside_lines(result: dict, splits: dict) -> list[str]:
    """Rendered-frame figures beside the simulated-marker ones (vs the true surface, mm², means)."""
    from lipgen.experiments.table51_stats import SPLITS

    lines = ["## Beside simulated markers (table51-splits), vs the true surface, mm² (mean over seeds)", "",
             "| split | observed | 10 modes: frames / markers | combined: frames / markers | "
             "physics: frames / markers |", "|---|---|---|---|---|"]
    for split in SPLITS:
        for row, cells in result["summary"][split].items():
            sim = splits["summary"][split].get(row)
            if sim is None:
                continue
            lines.append(f"| {split} | {row} | " + " | ".join(
                f"{cells[c]['truth'][0]:.3g} / {sim[c]['truth'][0]:.3g}"
                for c in ("modes", "combined", "physics_force")) + " |")
    lines.append("")
    return lines
