"""Table 5.1 through the whole pipeline (lipgen experiment table51-pipeline).

The invariant: the figures of a seed equal an independent scoring of the same reconstructed
fields (the reconstructions written to disk, reloaded; the learned prior rebuilt from the training
fields by an SVD here; the LLSE and the error per hidden DOF written out in numpy).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from lipgen.experiments.table51_pipeline import PipelineSettings, dataset_settings, run_pipeline, seed_record
from lipgen.experiments.table51_splits import ESTIMATORS, SPLITS, mean_interval


@pytest.fixture(scope="module")
def _egl():
    pytest.importorskip("cv2")
    from lipgen.rig.render import import_pyrender

    try:
        import_pyrender()
    except Exception as exc:  # pragma: no cover - depends on the machine
        pytest.skip(f"no offscreen rendering: {exc}")


def _independent(work, split: str, frames, n_modes: int, axes: str, hidden_free) -> dict:
    """{"modes": mm², "full": mm²} vs the true surface for the "{axes} (16 points)" row, in numpy."""
    from lipgen.dataset.layout import Dataset
    from lipgen.recon.pipeline import Reconstruction, model_mesh

    mesh = model_mesh()
    train = Reconstruction.load(work / "s0_train.recon.npz")
    F = len(train.fields)
    X = train.fields.reshape(F, -1)
    X = X[np.all(np.isfinite(X), axis=1)]
    mean = X.mean(axis=0)
    _, sv, Vt = np.linalg.svd(X - mean, full_matrices=False)
    priors = {"modes": (Vt[:n_modes].T * sv[:n_modes] ** 2) @ Vt[:n_modes],
              "full": (Vt.T * sv**2) @ Vt}  # covariances up to a scale, which the LLSE ignores
    recon = Reconstruction.load(work / f"s0_{split}.recon.npz")
    if split == "utterance":  # the same subject: expressed in the training recording's frame of reference
        from lipgen.recon.rereference import renormalize

        recon = renormalize(recon, train)
    ds = Dataset(work / f"s0_{split}")
    n = mesh.n_nodes
    true = np.stack([ds.truth(f)["vertices"][:n] for f in range(len(ds))]) - ds.mesh.vertices[:n]
    rest = mesh.vertices[mesh.markers]
    ax = ["xyz".index(a) for a in axes]
    out = {k: [] for k in priors}
    for f in frames:
        seen = np.flatnonzero(recon.visible[f])
        if len(seen) == 0 or not np.all(np.isfinite(recon.fields[f])):
            continue
        d = (3 * np.asarray(mesh.markers)[seen][:, None] + np.array(ax)).ravel()
        hid = np.setdiff1d(hidden_free, d)
        y = (recon.markers[f, seen] - rest[seen])[:, ax].ravel()
        for k, C in priors.items():
            est = mean + C[:, d] @ np.linalg.pinv(C[np.ix_(d, d)], hermitian=True) @ (y - mean[d])
            out[k].append(np.mean((est[hid] - true[f].ravel()[hid]) ** 2))
    return {k: float(np.mean(v)) for k, v in out.items()}


_SMALL = dict(seeds=(0, 1), n_train=12, n_test=10, lead_in=0, n_modes=4, calib_frames=4, size=(480, 360))


def _check_seed_record(work, s, physics, record):
    """The figures of ``record`` (seed 0 of ``s``, made in ``work``) equal the independent scoring,
    every cell is there, the training recording re-normalised by itself is itself, a second call
    gives the same figures, and the default settings' cells equal the LLSE written out."""
    for split in SPLITS:
        for axes in ("xy", "yz"):
            want = _independent(work, split, record["test_frames"][split], s.n_modes, axes,
                                physics.free_dofs)
            got = record[split][f"{axes} (16 points)"]
            for k in ("modes", "full"):
                assert got[k]["truth"] == pytest.approx(want[k], rel=1e-6), (split, axes, k)
        for cells in record[split].values():
            assert set(cells) == set(ESTIMATORS)
            for c in cells.values():
                assert np.isfinite(c["truth"]) and c["truth"] > 0
    # the training recording re-normalised with its own reference is itself again
    from lipgen.recon.pipeline import Reconstruction
    from lipgen.recon.rereference import renormalize

    train = Reconstruction.load(work / "s0_train.recon.npz")
    same = renormalize(train, train, physics)
    assert np.allclose(same.markers, train.markers, atol=1e-6, equal_nan=True)
    assert np.allclose(same.fields, train.fields, atol=1e-6, equal_nan=True)
    # a second call reuses the reconstructions on disk and gives the same figures
    again = seed_record(s, 0, work, physics, progress=False)
    assert again["utterance"] == record["utterance"] and again["subject"] == record["subject"]
    # the defaults (metric scale, modes from measured markers) with the measured noise, on the same data
    _check_defaults(work, physics)


@pytest.mark.slow(cover="tests/test_table51_pipeline.py::test_seed_record_scores_like_numpy_on_one_recording_thrice")
@pytest.mark.render
def test_seed_record_equals_independent_scoring(tmp_path, _egl):
    from lipgen.fem import Physics
    from lipgen.recon.pipeline import model_mesh

    s = PipelineSettings(**_SMALL, rest="model", learning="all", noise="none")
    physics = Physics(model_mesh())
    record = seed_record(s, 0, tmp_path, physics, progress=False)
    # the three datasets: subject seed and motion as documented
    made = {p: json.loads((tmp_path / f"s0_{p}" / "manifest.json").read_text())["settings"] for p in
            ("train", "utterance", "subject")}
    assert made["train"]["subject_seed"] == made["utterance"]["subject_seed"] == 0
    assert made["subject"]["subject_seed"] == 1000
    assert len({made[p]["seed"] for p in made}) == 3
    assert dataset_settings(s, 0)["train"].frames == s.n_train
    _check_seed_record(tmp_path, s, physics, record)


@pytest.mark.render
def test_seed_record_scores_like_numpy_on_one_recording_thrice(tmp_path, _egl):
    """The scoring of a seed on the three parts made from one recording (the training one, its
    dataset and reconstruction copied as the utterance and the other subject: seed_record reuses
    what is in its folder): a third of the rendering and reconstruction of the full check, which
    the slow set runs on three recordings. What the datasets are made with is read from
    dataset_settings."""
    import shutil

    from lipgen.experiments.table51_pipeline_data import make_dataset, reconstruct
    from lipgen.fem import Physics
    from lipgen.recon.pipeline import model_mesh

    s = PipelineSettings(**_SMALL, rest="model", learning="all", noise="none")
    made = dataset_settings(s, 0)
    assert made["train"].subject_seed == made["utterance"].subject_seed == 0
    assert made["subject"].subject_seed == 1000 and made["train"].frames == s.n_train
    assert len({made[p].seed for p in made}) == 3 and made["subject"].frames == s.n_test
    make_dataset(tmp_path / "s0_train", made["train"], 1, False)
    reconstruct(tmp_path / "s0_train", False)
    for part in ("utterance", "subject"):
        shutil.copytree(tmp_path / "s0_train", tmp_path / f"s0_{part}")
        shutil.copy(tmp_path / "s0_train.recon.npz", tmp_path / f"s0_{part}.recon.npz")
    physics = Physics(model_mesh())
    record = seed_record(s, 0, tmp_path, physics, progress=False)
    assert record["test_frames"]["subject"] == list(range(10))
    _check_seed_record(tmp_path, s, physics, record)


def _check_defaults(work, physics):
    """The default settings' (with the measured noise only) 10-mode and full-covariance cells equal the
    LLSE with a noise term written out in numpy (Σ_xo (Σ_oo + R)⁻¹), on the recordings normalised and
    the model fitted as documented."""
    from lipgen.dataset.layout import Dataset
    from lipgen.experiments.table51_pipeline_data import normalised
    from lipgen.modes.missing import second_difference_noise
    from lipgen.modes.model import ModeModel
    from lipgen.recon.pipeline import Reconstruction
    from lipgen.recon.rest import measured_markers

    s = PipelineSettings(**_SMALL, noise="measured")
    record = seed_record(s, 0, work, physics, progress=False)
    recons = {p: Reconstruction.load(work / f"s0_{p}.recon.npz") for p in ("train", *SPLITS)}
    recons, rests = normalised(s, recons, physics)
    train, mesh = recons["train"], physics.mesh
    F, P = len(train.fields), len(mesh.markers)
    ok = np.all(np.isfinite(train.fields.reshape(F, -1)), axis=1)
    meas = measured_markers(train)
    model = ModeModel(4).fit_measured(train.fields[ok], meas[ok], physics)
    R = second_difference_noise(train.markers.reshape(F, -1), np.repeat(meas, 3, axis=1)).reshape(P, 3)
    R = np.where(np.isfinite(R), R, np.nanmedian(R, axis=0))
    priors = {"modes": model.covariance(4).matrix(), "full": model.covariance("full").matrix()}
    learned = model.marker_coverage_ > 0
    meas_test = {split: measured_markers(recons[split]) for split in SPLITS}
    for split in SPLITS:
        recon, ds = recons[split], Dataset(work / f"s0_{split}")
        n = mesh.n_nodes
        true = np.stack([ds.truth(f)["vertices"][:n] for f in range(len(ds))]) - ds.mesh.vertices[:n]
        for axes in ("xy", "yz"):
            ax = np.array(["xyz".index(a) for a in axes])
            out = {k: [] for k in priors}
            at_markers = {k: [] for k in priors}
            for f in record["test_frames"][split]:
                seen = np.flatnonzero(recon.visible[f, :P])
                if len(seen) == 0 or not np.all(np.isfinite(recon.fields[f])):
                    continue
                hid = np.setdiff1d(physics.free_dofs, (3 * mesh.markers[seen][:, None] + ax).ravel())
                mk = np.flatnonzero(meas_test[split][f])  # the hidden coordinates of the measured markers
                md = (3 * mesh.markers[mk][:, None] + np.arange(3)).ravel()
                keep = np.isin(md, hid)
                use = seen[learned[seen]]
                d = (3 * mesh.markers[use][:, None] + ax).ravel()
                rest = mesh.vertices[mesh.markers] if rests[split] is None else rests[split]
                y = (recon.markers[f, use] - rest[use])[:, ax].ravel()
                for k, C in priors.items():
                    Soo = C[np.ix_(d, d)] + np.diag(R[use][:, ax].ravel())
                    gain = np.linalg.solve(Soo, y - model.mean_[d])
                    est = model.mean_ + C[:, d] @ gain
                    out[k].append(np.mean((est[hid] - true[f].ravel()[hid]) ** 2))
                    measured = (recon.markers[f, mk] - rest[mk]).ravel()[keep]
                    at_markers[k].append(np.mean((est[md[keep]] - measured) ** 2))
            for k in priors:
                got = record[split][f"{axes} (16 points)"][k]["truth"]
                assert got == pytest.approx(float(np.mean(out[k])), rel=1e-6), (split, axes, k)
                got = record[split][f"{axes} (16 points)"][k]["markers"]
                assert got == pytest.approx(float(np.mean(at_markers[k])), rel=1e-6), (split, axes, k)


@pytest.mark.slow(cover="tests/test_table51_pipeline.py::test_seed_record_scores_like_numpy_on_one_recording_thrice")
@pytest.mark.render
def test_five_seed_pipeline(tmp_path, _egl):
    from lipgen.experiments.table51_pipeline import write_pipeline_report

    result = run_pipeline(PipelineSettings(), tmp_path / "work", progress=False)
    assert len(result["per_seed"]) == 5
    for split in SPLITS:
        for row, cells in result["summary"][split].items():
            for col in ESTIMATORS:
                vals = [r[split][row][col]["truth"] for r in result["per_seed"]]
                assert cells[col]["truth"] == pytest.approx(mean_interval(vals))
                assert cells[col]["truth"][1] <= cells[col]["truth"][0] <= cells[col]["truth"][2]
    md = write_pipeline_report(result, tmp_path / "out")
    assert "Utterance split" in open(md).read()


@pytest.mark.parametrize("bad, match", [
    ({"seeds": (3,)}, "2 or more distinct"),
    ({"seeds": (1, 1)}, "2 or more distinct"),
    ({"preset": "easy"}, "preset must be"),
    ({"window": 5}, "window must be >= 10"),
    ({"n_test": 15, "lead_in": 10}, "n_test >= lead_in"),
    ({"n_modes": 150}, "n_modes < n_train"),
    ({"utterance_reference": "test"}, "utterance_reference must be"),
    ({"rest": "first"}, "rest must be one of"),
    ({"noise": "big"}, "noise must be one of"),
])
def test_bad_settings(bad, match):
    with pytest.raises(ValueError, match=match):
        PipelineSettings(**bad)


def test_cli_refuses_a_missing_splits_file(tmp_path, capsys):
    from lipgen.cli import main

    status = main(["experiment", "table51-pipeline", "--splits", str(tmp_path / "nope.json"), "--out",
                   str(tmp_path / "o")])
    assert status != 0 and "nope.json" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_report_from_seed_records(tmp_path):
    """The report of made-up records: their means appear, beside a splits result."""
    from lipgen.experiments.table51_pipeline import ROW_NAMES, write_pipeline_report
    from lipgen.experiments.table51_splits import aggregate

    rng = np.random.default_rng(0)
    refs = ("truth", "reach", "truth_relative", "markers")
    per_seed = [{"seed": k, "variance_captured": 0.99, "accepted_share": {p: 0.9 for p in ("train", *SPLITS)},
                 **{split: {row: {c: {r: float(rng.uniform(1, 2)) for r in refs} for c in ESTIMATORS}
                            for row in ROW_NAMES.values()} for split in SPLITS}}
                for k in range(3)]
    result = {"settings": {**PipelineSettings().__dict__, "n_windows": 3, "size": [640, 480]},
              "mm_per_unit": 10.0, "per_seed": per_seed, **aggregate(per_seed, list(ROW_NAMES.values()))}
    md = open(write_pipeline_report(result, tmp_path, splits=result)).read()
    mean = np.mean([r["subject"]["xy (16 points)"]["modes"]["truth"] for r in per_seed])
    assert f"{mean:.3g} [" in md
    assert f"{mean:.3g} / {mean:.3g}" in md  # beside itself
    assert json.loads((tmp_path / "pipeline.json").read_text())["per_seed"][2]["seed"] == 2
    # the x-y / y-z order against each reference, the measured markers included
    for ref in ("truth", "reach", "markers"):
        u = [r["utterance"] for r in per_seed]
        o = np.mean([t["xy (16 points)"]["modes"][ref] / t["yz (16 points)"]["modes"][ref] for t in u])
        assert f"{o:.3g} [" in md
    assert "vs the measured markers" in md and "refer to that kind of reference" in md
