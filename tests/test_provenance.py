"""A model records what it was trained on; evaluate refuses to test on those frames."""

import json

import numpy as np
import pytest

from lipgen.dataset.manifest import dataset_digest
from lipgen.evaluate.scoring import _check_provenance
from lipgen.modes.model import ModeModel


def _model(tmp_path):
    rng = np.random.default_rng(0)
    return ModeModel(3).fit(rng.normal(size=(20, 30)))


def test_provenance_round_trip_and_old_files(tmp_path):
    m = _model(tmp_path)
    m.save(tmp_path / "old.npz")
    assert ModeModel.load(tmp_path / "old.npz").provenance_ is None  # files without it still load
    m.provenance_ = {"dataset": "/data/a", "dataset_id": "ab" * 32, "frames": [0, 1, 2]}
    m.save(tmp_path / "m.npz")
    assert ModeModel.load(tmp_path / "m.npz").provenance_ == m.provenance_


def test_evaluate_refuses_trained_frames(tmp_path):
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "manifest.json").write_text(json.dumps({"seed": 1}))
    other = tmp_path / "other"
    other.mkdir()
    (other / "manifest.json").write_text(json.dumps({"seed": 2}))
    m = _model(tmp_path)
    m.provenance_ = {"dataset": str(ds), "dataset_id": dataset_digest(ds), "frames": list(range(140))}
    _check_provenance(m, ds, np.arange(140, 150))  # the held-out tail: fine
    _check_provenance(m, other, np.arange(130, 150))  # another dataset: its frames are new
    with pytest.raises(ValueError, match=r"trained on frames \[130, 131.* \(10 of the 20 test frames\)"):
        _check_provenance(m, ds, np.arange(130, 150))
    m.provenance_ = None
    _check_provenance(m, ds, np.arange(130, 150))  # unknown provenance: nothing to check
