"""Data of :mod:`lipgen.experiments.table51_pipeline`: datasets made and reconstructed once, the
frames of reference and rests of the recordings, and the marker displacement error."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["make_dataset", "reconstruct", "normalised", "marker_error", "model_line"]


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

    recon = reconstruct_dataset(path, progress=progress, reference_frames=range(len(Dataset(path))))
    recon.save(file)
    return recon


def normalised(s, recons: dict, physics) -> tuple[dict, dict]:
    """The reconstructions in the frame of reference of ``s`` and the rest (P, 3) of each (None:
    the model's): ``rest="quiet"`` re-normalises at scale 1 from the training recording's quiet
    rest (the other subject from its own), ``"metric"`` at scale 1 from the model's rest, else as
    reconstructed (the utterance re-normalised with
    the training reference if ``utterance_reference="train"``)."""
    from lipgen.recon.rereference import renormalize
    from lipgen.recon.rest import metric_renormalize

    out = dict(recons)
    if s.rest == "model":
        if s.utterance_reference == "train":
            out["utterance"] = renormalize(recons["utterance"], recons["train"], physics)
        return out, dict.fromkeys(recons)
    if s.rest == "metric":
        M = physics.mesh.vertices[physics.mesh.markers]
        ref = recons["train"] if s.utterance_reference == "train" else None
        out["train"], _ = metric_renormalize(recons["train"], physics, rest=M)
        out["utterance"], _ = metric_renormalize(recons["utterance"], physics, rest=M, reference=ref)
        out["subject"], _ = metric_renormalize(recons["subject"], physics, rest=M)
        return out, dict.fromkeys(recons)
    out["train"], rest = metric_renormalize(recons["train"], physics)
    rests = {"train": rest}
    if s.utterance_reference == "train":
        out["utterance"], rests["utterance"] = metric_renormalize(recons["utterance"], physics, rest=rest,
                                                                  reference=recons["train"])
    else:
        out["utterance"], rests["utterance"] = metric_renormalize(recons["utterance"], physics)
    out["subject"], rests["subject"] = metric_renormalize(recons["subject"], physics)
    return out, rests


def marker_error(recon, ds, mesh, rest=None) -> dict:
    """RMS error (mm) of the reconstructed marker displacements (normalised markers minus ``rest``,
    default the model's rest) against the true ones (model-frame marks minus the subject's rest) over the
    accepted sightings; ``"after_offset"``: once each marker's mean error over the frames (a
    constant offset, e.g. from the normalisation's reference frame) is taken out."""
    from lipgen.evaluate.scoring import load_truth

    P = len(mesh.markers)
    truth = load_truth(ds)
    rest = mesh.vertices[mesh.markers] if rest is None else rest
    err = (recon.markers - rest) - (truth["marks_model"][:, :P] - ds.rest_marks()[:P])
    err = np.where(recon.visible[..., None], err, np.nan)
    seen = np.any(recon.visible, axis=0)
    offset = np.zeros((P, 3))
    offset[seen] = np.nanmean(err[:, seen], axis=0)
    with np.errstate(invalid="ignore"):
        return {"rms": float(np.sqrt(np.nanmean(np.sum(err**2, axis=-1)))),
                "after_offset": float(np.sqrt(np.nanmean(np.sum((err - offset) ** 2, axis=-1))))}


def model_line(s: dict) -> str:
    """The report's sentence on the rest, the learning and the noise term (settings ``s``)."""
    rest = {"quiet": "Displacements are measured from the subject's rest estimated on the training "
                     "recording's quiet frames, at the rig's metric scale (the other subject: from its own "
                     "recording; `lipgen.recon.rest`)",
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
