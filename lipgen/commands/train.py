"""``lipgen train``: learn displacement modes from a reconstruction (thesis §4.2)."""

from __future__ import annotations

import argparse
import sys

from lipgen.commands._output import check_file_output, check_not_input

_EPILOG = """\
The last --test-frames frames (default: 10, or a fifth of short sequences, as the thesis's
140 + 10) are held out for lipgen evaluate; frames without a field (too few markers seen) are
skipped. The reconstruction's normalisation reference frame must be a training frame (lipgen
reconstruct chooses it outside the same default tail; give both the same --test-frames), and so
must the frames its rest was estimated on (lipgen reconstruct --rest recording). The rest the
fields are measured from is recorded in the model's provenance.

example:
  lipgen train recon.npz --out model.npz --modes 10
"""


def add_parser(sub) -> None:
    p = sub.add_parser("train", help="learn displacement modes (ModeModel) from a reconstruction",
                       description="Fit the learned modes (snapshot PCA, thesis Appendix B) to the training "
                       "frames of a reconstruction written by lipgen reconstruct.",
                       epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recon", help="reconstruction file from lipgen reconstruct (.npz)")
    p.add_argument("--out", required=True, help="model file to write (.npz)")
    p.add_argument("--modes", type=int, default=10, help="number of modes (default 10)")
    p.add_argument("--test-frames", type=int, default=None, help="frames held out at the end")
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from lipgen.evaluate.scoring import default_test_frames, split_frames
    from lipgen.modes.model import ModeModel
    from lipgen.recon.pipeline import Reconstruction, model_mesh

    out = check_file_output(args.out, args.force)
    check_not_input(out, (args.recon,))
    recon = Reconstruction.load(args.recon)
    F = len(recon.fields)
    T = default_test_frames(F) if args.test_frames is None else args.test_frames
    train, test = split_frames(recon.fields, T)
    from lipgen.recon.restsource import rest_frames_held_out

    held = rest_frames_held_out(recon, range(F - T, F))
    if held:
        raise ValueError(f"the reconstruction's rest is the median of frames including {held}, which "
                         f"--test-frames {T} holds out (frames {F - T}-{F - 1}): the test frames would "
                         f"have shaped the training data; reconstruct again with lipgen reconstruct "
                         f"--test-frames {T}")
    ref = recon.info.get("normalisation", {}).get("reference_frame")
    if ref is not None and ref >= len(recon.fields) - T:
        raise ValueError(f"the reconstruction's normalisation took its reference frame {ref} from the "
                         f"last {T} frames, which --test-frames {T} holds out as test frames; reconstruct "
                         f"again with lipgen reconstruct --test-frames {T} (or name --reference-frames)")
    mesh = model_mesh(recon.info["mesh_source"])
    model = ModeModel(args.modes).fit(recon.fields[train], mesh=mesh)
    model.provenance_ = _provenance(recon, args.recon, train)
    model.save(out)
    share = 100 * model.explained_variance_ratio_.sum()
    sys.stdout.write(f"trained {len(model.components_)} modes on {len(train)} frames ({share:.2f}% of the "
                     f"variance; displacements from {model.provenance_['rest']}); {len(test)} test frames "
                     f"held out -> {out}\n")
    return 0


def _provenance(recon, recon_path, train) -> dict:
    """What the model is trained on: the dataset (path and manifest digest) and its frames."""
    import os

    from lipgen.dataset.manifest import dataset_digest

    dataset = recon.info.get("dataset")
    try:
        digest = dataset_digest(dataset) if dataset else None
    except OSError:  # the dataset has moved: the frames are still recorded
        digest = None
    from lipgen.recon.restsource import rest_line

    return {"dataset": dataset, "dataset_id": digest, "recon": os.path.abspath(recon_path),
            "frames": [int(f) for f in train], "rest": rest_line(recon),
            "rest_kind": recon.info.get("rest_source", {}).get("kind", "model")}
