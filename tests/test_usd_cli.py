"""`lipgen export-usd` from the command line: modes, viseme scripts and a dataset's ground truth."""

import numpy as np
import pytest

pytest.importorskip("pxr")

from usd_common import expected_points  # noqa: E402

from lipgen.modes.model import ModeModel  # noqa: E402
from lipgen.usd import export as usd  # noqa: E402

pytestmark = pytest.mark.usd


def test_command_line_export(tmp_path, usd_mesh, usd_fitted, capsys):
    from lipgen.cli import main

    model, weights = usd_fitted
    usd_mesh.save(tmp_path / "mesh.npz")
    model.save(tmp_path / "model.npz")
    np.save(tmp_path / "w.npy", weights)
    np.savez(tmp_path / "p.npz", points=expected_points(usd_mesh, model, weights))
    out = tmp_path / "lips.usda"
    code = main(["export-usd", "--mesh", str(tmp_path / "mesh.npz"), "--model", str(tmp_path / "model.npz"),
                 "--weights", str(tmp_path / "w.npy"), "--points", str(tmp_path / "p.npz"), "--fps", "25",
                 "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "24 frame(s) at 25 fps, blend shapes + baked points" in text and "0 error(s)" in text
    anim = usd.read_animation(out)
    assert anim.fps == 25 and np.abs(anim.points - expected_points(usd_mesh, model, weights)).max() < 1e-4
    np.save(tmp_path / "bad.npy", weights[:, :4])
    code = main(["export-usd", "--mesh", str(tmp_path / "mesh.npz"), "--model", str(tmp_path / "model.npz"),
                 "--weights", str(tmp_path / "bad.npy"), "--out", str(tmp_path / "bad.usdc")])
    err = capsys.readouterr().err
    assert code == 1 and "weights must have shape (F, 10)" in err and not (tmp_path / "bad.usdc").exists()
    with pytest.raises(SystemExit) as exit_info:
        main(["export-usd", "--help"])
    assert exit_info.value.code == 0 and "--weight-range" in capsys.readouterr().out


def test_command_line_viseme_script(tmp_path, usd_mesh, usd_fitted, capsys):
    """--script: visemes -> activations -> the synthetic subject -> projected on the modes. The
    blend-shape animation is then the least-squares fit of the simulated motion within the modes'
    span: its residual against the baked simulation (--bake) is orthogonal to every mode."""
    from pxr import Usd

    from lipgen.cli import main

    model, _ = usd_fitted
    model.save(tmp_path / "model.npz")
    out = tmp_path / "speech.usdc"
    code = main(["export-usd", "--model", str(tmp_path / "model.npz"), "--script", "AA:0.3 EE OO M",
                 "--bake", "--fps", "30", "--out", str(out)])
    assert code == 0, capsys.readouterr()
    assert "27 frame(s) at 30 fps, blend shapes + baked points" in capsys.readouterr().out
    skel = usd.read_animation(out).points
    stage = Usd.Stage.Open(str(out))
    stage.GetDefaultPrim().GetVariantSets().GetVariantSet("encoding").SetVariantSelection("bakedPoints")
    stage.GetRootLayer().Export(str(tmp_path / "baked.usdc"))
    truth = usd.read_animation(tmp_path / "baked.usdc").points
    assert np.abs(truth - usd_mesh.vertices).max() > 1.0  # the lips really move (mm)
    residual = (truth - skel).reshape(len(truth), -1)
    along_modes = residual @ model.components_.T
    assert np.abs(along_modes).max() < 1e-4 * np.abs(residual).max() + 1e-4
    usd_mesh.save(tmp_path / "m.npz")
    assert main(["export-usd", "--model", str(tmp_path / "model.npz"), "--script", "AA", "--mesh",
                 str(tmp_path / "m.npz"), "--out", str(tmp_path / "x.usda")]) == 1
    assert "--script needs the procedural lips" in capsys.readouterr().err


def test_command_line_dataset_ground_truth(tmp_path, usd_mesh, usd_fitted, capsys):
    """--dataset: the ground-truth vertices of a (tiny) generated dataset, baked, at its fps;
    a model of another mesh is refused with the reason."""
    from lipgen.cli import main
    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import Dataset, GenerateSettings

    root = generate(tmp_path / "ds", GenerateSettings(frames=3, seed=2, size=(160, 120), calib_frames=0,
                                                      fps=25), progress=False)
    ds = Dataset(root)
    truth = np.stack([f.truth["vertices"] for f in ds])
    out = tmp_path / "truth.usdc"
    assert main(["export-usd", "--dataset", str(root), "--out", str(out)]) == 0
    assert "3 frame(s) at 25 fps, baked points" in capsys.readouterr().out
    anim = usd.read_animation(out)
    assert anim.fps == 25 and not anim.skinned
    assert np.array_equal(anim.points, truth.astype(np.float32).astype(np.float64))
    model, _ = usd_fitted  # fitted on lip_mesh(0); the dataset's subject is the finer lip_mesh(1)
    model.save(tmp_path / "model.npz")
    code = main(["export-usd", "--dataset", str(root), "--model", str(tmp_path / "model.npz"),
                 "--out", str(tmp_path / "x.usdc")])
    assert code == 1 and "nodes" in capsys.readouterr().err and not (tmp_path / "x.usdc").exists()
    # A model of the subject's own mesh: the truth also goes onto its modes (2 modes span 3 frames,
    # so the blend shapes give the truth back).
    ModeModel(2).fit(truth - ds.mesh.vertices, mesh=ds.mesh).save(tmp_path / "own.npz")
    assert main(["export-usd", "--dataset", str(root), "--model", str(tmp_path / "own.npz"),
                 "--out", str(tmp_path / "both.usdc")]) == 0
    assert "blend shapes + baked points" in capsys.readouterr().out
    skel = usd.read_animation(tmp_path / "both.usdc")
    assert skel.skinned and np.abs(skel.points - truth).max() < 1e-4
