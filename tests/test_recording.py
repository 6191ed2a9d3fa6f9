"""Reconstruction of data without truth (a user's recording), and no silent loss of markers.

One small dataset (480x360, 8 frames, 5 calibration frames) is rendered once for the module;
the tests work on copies of it: with the truth removed, with a marker's dot erased, as a video.
"""

import shutil

import numpy as np
import pytest

from lipgen.cli import main
from lipgen.errors import DatasetError
from lipgen.recon.pipeline import reconstruct_dataset

pytest.importorskip("cv2")
pytestmark = pytest.mark.render

FRAMES = 8


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from lipgen.rig.render import import_pyrender

    try:
        import_pyrender()
    except Exception as exc:  # no GL here: the rendering tests cannot run
        pytest.skip(f"no offscreen rendering: {exc}")
    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import GenerateSettings

    path = tmp_path_factory.mktemp("rec") / "ds"
    generate(path, GenerateSettings(frames=FRAMES, seed=5, size=(640, 480), calib_frames=5), workers=1,
             progress=False)
    return path


@pytest.fixture(scope="module")
def recon(dataset):
    return reconstruct_dataset(dataset)


def _without_truth(dataset, tmp_path):
    dst = tmp_path / "notruth"
    shutil.copytree(dataset, dst)
    shutil.rmtree(dst / "truth")
    for f in (dst / "calib").glob("*.npz"):
        f.unlink()
    return dst


def test_a_dataset_without_truth_reconstructs_the_same(tmp_path, dataset, recon):
    from lipgen.dataset.layout import Dataset

    bare = _without_truth(dataset, tmp_path)
    ds = Dataset(bare)
    assert not ds.has_truth and Dataset(dataset).has_truth
    assert ds[0].truth == {} and ds.missing(truth=False) == [] and len(ds.missing()) == FRAMES
    again = reconstruct_dataset(bare)
    for name in ("uv", "lab_points", "markers", "fields"):
        a, b = getattr(recon, name), getattr(again, name)
        assert np.array_equal(np.isnan(a), np.isnan(b)), name
        np.testing.assert_allclose(b, a, atol=1e-6, rtol=0, equal_nan=True, err_msg=name)


def test_train_and_show_work_without_truth_and_evaluate_says_it_needs_it(tmp_path, dataset):
    bare = _without_truth(dataset, tmp_path)
    rec, model, rep = tmp_path / "r.npz", tmp_path / "m.npz", tmp_path / "rep"
    assert main(["reconstruct", str(bare), "--out", str(rec), "--no-progress"]) == 0
    assert main(["train", str(rec), "--out", str(model), "--modes", "2", "--test-frames", "2"]) == 0
    pic = tmp_path / "f.png"
    assert main(["show", str(bare), "--frame", "1", "--recon", str(rec), "--out", str(pic)]) == 0
    assert pic.stat().st_size > 1000
    with pytest.raises(DatasetError, match="no ground truth.*lipgen evaluate"):
        main(["-vv", "evaluate", str(bare), "--model", str(model), "--recon", str(rec), "--out", str(rep)])
    assert not rep.exists(), "nothing is written when the truth is missing"
