"""``lipgen generate`` / ``lipgen show`` and the dataset reader.

Small datasets (few frames, small images): the rendered dots are found in the images by plain
thresholding and compared with the truth projections; two runs (one in-process, one with two
worker processes) and a run killed part-way then resumed must write identical bytes.
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from lipgen.cli import main
from lipgen.dataset.layout import Dataset, GenerateSettings, validate_manifest
from lipgen.errors import DatasetError
from lipgen.rig.camera import VIEWS

pytestmark = pytest.mark.render
pytest.importorskip("lipgen.rig.render")
pytest.importorskip("lipgen.subject.motion")

TINY = GenerateSettings(frames=14, seed=3, size=(160, 120), calib_frames=1, script="AA:0.2 OO:0.2 M F")


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    from lipgen.dataset.generate import generate

    return generate(tmp_path_factory.mktemp("ref") / "ds", TINY, progress=False)


def test_layout_manifest_and_reader(reference):
    ds = Dataset(reference)
    m = ds.manifest
    validate_manifest(m)
    assert m["units"] == "mm" and m["convention"] == "opencv" and m["seed"] == 3
    assert m["mesh"]["topology_id"] == ds.mesh.topology_id and m["mesh"]["resolution"] == 1
    assert len(ds) == 14 and ds.missing() == [] and len(m["frames"]) == 14
    fr = ds[5]
    assert fr.image.shape == (120, 160, 3) and fr.index == 5 and fr.time == pytest.approx(5 / 30)
    k = len(ds.marks)
    assert k == 17 and list(fr.mark_names) == list(ds.marks)
    for name, shape in (("uv", (2, k, 2)), ("uv_raw", (2, k, 2)), ("visible", (2, k)), ("depth", (2, k)),
                        ("marks_world", (k, 3)), ("vertices", (ds.mesh.n_nodes, 3)), ("pose", (4, 4)),
                        ("activations", (len(m["actions"]),)), ("dot_visible_fraction", (2, k))):
        assert fr.truth[name].shape == shape, name
    # the truth is self-consistent: world marks are the posed model-frame marks, projected by the rig
    P = fr.pose
    np.testing.assert_allclose(fr.marks_world, fr.marks_model @ P[:3, :3].T + P[:3, 3], atol=1e-9)
    np.testing.assert_allclose(fr.marks_model[:16], fr.vertices[ds.mesh.markers], atol=1e-12)
    np.testing.assert_allclose(ds.rig.project(fr.marks_world)[0], fr.uv, atol=1e-9)
    assert list(fr.views) == list(VIEWS)
    alone = ds.truth(5)  # the truth without the image
    assert alone.keys() == fr.truth.keys() and all(np.array_equal(alone[k], fr.truth[k]) for k in alone)
    with pytest.raises(IndexError):
        ds.truth(14)
    assert np.array_equal(ds.truth(np.int64(-9))["uv"], fr.truth["uv"])   # numpy and negative indices
    assert [f.index for f in ds] == list(range(14))
    cal = ds.calibration()
    assert len(cal) == 1 and cal[0].truth["corners_world"].shape == (54, 3)
    A, b = cal[0].truth["A"], cal[0].truth["b"]
    np.testing.assert_allclose(cal[0].truth["corners_board"] @ A.T + b, cal[0].truth["corners_world"],
                               atol=1e-9)
    assert ds.board().inner_cols == 9
    with pytest.raises(IndexError):
        ds[14]


def test_a_frames_unreadable_truth_is_named(reference, tmp_path):
    import shutil

    copy = tmp_path / "ds"
    shutil.copytree(reference, copy)
    ds = Dataset(copy)
    bad = ds.file(ds.manifest["frames"][3]["truth"])
    bad.write_bytes(b"not an npz")
    with pytest.raises(DatasetError, match=bad.name):
        ds.truth(3)
    assert ds.truth(2).keys() == ds[2].truth.keys()   # the other frames still read


def test_same_settings_same_bytes_with_two_workers(reference, tmp_path):
    from lipgen.dataset.generate import generate

    other = generate(tmp_path / "ds", TINY, workers=2, progress=False)
    a, b = _files(reference), _files(other)
    assert a.keys() == b.keys()
    different = [name for name in a if a[name] != b[name]]
    assert not different, f"files differ between runs: {different[:5]}"


def test_the_calibration_boards_are_drawn_once(tmp_path, monkeypatch):
    """``prepare_dataset`` draws them (to check they fit the rig) and hands them to the renderers:
    with lens frames a draw is about a second of rejection sampling, once per worker before."""
    from dataclasses import replace

    import lipgen.rig.target as target
    from lipgen.dataset.generate import generate

    calls, real = [], target.calibration_targets
    monkeypatch.setattr(target, "calibration_targets", lambda *a, **k: calls.append(a) or real(*a, **k))
    ds = generate(tmp_path / "ds", replace(TINY, frames=2, calib_frames=2), progress=False)
    assert len(calls) == 1 and len(list((ds / "calib").glob("*.png"))) == 2


def test_resume_after_a_kill_completes_identically(reference, tmp_path):
    from lipgen.dataset.generate import generate

    out = tmp_path / "ds"
    args = [sys.executable, "-m", "lipgen", "generate", "--out", str(out), "--frames", "14", "--seed", "3",
            "--size", "160x120", "--calib-frames", "1", "--script", "AA:0.2 OO:0.2 M F", "--no-progress"]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        if len(list((out / "truth").glob("[0-9]*.npz"))) >= 4:
            proc.send_signal(signal.SIGKILL)
            break
        time.sleep(0.02)
    proc.wait()  # killed above, or finished: no load-dependent timeout
    written = sorted((out / "truth").glob("[0-9]*.npz"))
    if proc.returncode == 0:
        pytest.skip("the run finished before it could be killed")
    assert 4 <= len(written) < 14
    before = {p: p.stat().st_mtime_ns for p in written}
    # a killed run is an incomplete dataset: the reader says what is missing
    assert Dataset(out).missing()
    # without --resume the folder is refused and left alone
    with pytest.raises(DatasetError, match="--resume"):
        generate(out, TINY, progress=False)
    generate(out, TINY, resume=True, progress=False)
    assert {p: p.stat().st_mtime_ns for p in written} == before, "frames already written were redone"
    a, b = _files(reference), _files(out)
    assert a.keys() == b.keys(), set(a) ^ set(b)
    assert all(a[k] == b[k] for k in a)


def _threshold_centroids(img):
    """Dark blobs and their darkness-weighted centroids, from the image alone.

    The darkness is measured against the local shading (a plane fitted to a ring of pixels
    around the blob), so that a shading gradient does not pull the centroid.
    """
    g = img.astype(float).mean(axis=2)
    lab, n = ndimage.label(g < 60)
    out = []
    for k in range(1, n + 1):
        comp = lab == k
        region = ndimage.binary_dilation(comp, iterations=1)
        ring = ndimage.binary_dilation(region, iterations=2) & ~region & (lab == 0)
        ry, rx = np.nonzero(ring)
        coef, *_ = np.linalg.lstsq(np.column_stack([np.ones(len(rx)), rx, ry]), g[ry, rx], rcond=None)
        yy, xx = np.nonzero(region)
        w = np.clip(coef[0] + coef[1] * xx + coef[2] * yy - g[yy, xx], 0, None)
        out.append([np.sum(xx * w) / w.sum(), np.sum(yy * w) / w.sum()])
    return np.array(out)


@pytest.mark.parametrize("subject_seed", [None, 5])
def test_rendered_dots_found_by_thresholding_match_the_truth(tmp_path, subject_seed):
    from lipgen.dataset.generate import generate

    s = GenerateSettings(frames=4, seed=1, size=(480, 360), calib_frames=0, dot_diameter=3.0, noise=1.0,
                         subject_seed=subject_seed)
    ds = Dataset(generate(tmp_path / "ds", s, progress=False))
    if subject_seed is not None:  # the subject's own dots, recorded and at surface points
        assert ds.manifest["subject"]["subject_seed"] == subject_seed
        assert ds.dots is not None and ds.settings.subject_seed == subject_seed
        rest = ds.rest_marks()
        assert np.linalg.norm(rest - ds.mesh.vertices[ds.mesh.markers], axis=1).min() > 0.3
    else:
        assert "subject" not in ds.manifest and "subject_seed" not in ds.manifest["settings"]
    errors, eligible = [], 0
    for fr in ds:
        views = ds.rig.split_views(fr.image)
        for v in range(2):
            c = _threshold_centroids(views[v])
            uv, ok = fr.uv[v], fr.visible[v] & (fr.dot_visible_fraction[v] == 1)
            # dots that touch another in the image merge into one blob: leave those out
            gap = np.linalg.norm(uv[:, None] - uv[None], axis=2) + np.eye(len(uv)) * 1e9
            ok &= gap.min(axis=1) > 7
            d = np.linalg.norm(c[:, None] - uv[None], axis=2)
            # a dot seen edge-on at the silhouette can be too faint for the fixed threshold: it is
            # then not found (no blob within 3 px), which is the detector's miss, not a wrong truth
            found = ok & (d.min(axis=0) < 3.0)
            eligible += int(ok.sum())
            errors.append(c[d.argmin(axis=0)][found] - uv[found])
    err = np.vstack(errors)
    rms = np.sqrt(np.mean(np.sum(err**2, axis=1)))
    print(f"thresholded dot centroids: {rms:.3f} px RMS over {len(err)} of {eligible} dots")
    assert len(err) >= 30 and len(err) >= 0.95 * eligible and rms < 0.5
    assert np.abs(err.mean(axis=0)).max() < 0.2


def test_show_writes_a_picture(reference, tmp_path, capsys):
    out = tmp_path / "x.png"
    assert main(["show", str(reference), "--frame", "3", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["show", str(reference), "--frame", "3", "--out", str(out)]) == 1  # kept without --force
    assert "--force" in capsys.readouterr().err
    assert main(["show", str(reference), "--frame", "99", "--out", str(out), "--force"]) == 1
    assert "out of range" in capsys.readouterr().err


def test_bad_inputs_are_refused_and_nothing_is_overwritten(reference, tmp_path, capsys):
    from lipgen.dataset.generate import generate

    stranger = tmp_path / "stranger"
    stranger.mkdir()
    (stranger / "notes.txt").write_text("mine")
    with pytest.raises(DatasetError, match="not a lipgen dataset"):
        generate(stranger, TINY, progress=False)
    assert [p.name for p in stranger.iterdir()] == ["notes.txt"]
    before = _files(reference)
    with pytest.raises(DatasetError, match="--resume"):
        generate(reference, TINY, progress=False)
    with pytest.raises(DatasetError, match="different settings.*seed was 3, now 4"):
        generate(reference, GenerateSettings(**{**TINY.to_dict(), "seed": 4, "size": (160, 120),
                                                "board": (9, 6, 8.0)}), resume=True, progress=False)
    assert _files(reference) == before
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(DatasetError, match="cannot create the dataset folder"):
        generate(blocker / "ds", TINY, progress=False)
    with pytest.raises(ValueError, match="unknown viseme 'XX'"):
        GenerateSettings(script="AA XX")
    assert main(["generate", "--out", str(tmp_path / "v"), "--script", "AA QQ:0.2", "--frames", "3"]) == 1
    assert "unknown viseme" in capsys.readouterr().err
    with pytest.raises(ValueError, match="4:3"):
        GenerateSettings(size=(640, 360))


def test_a_rig_that_misses_the_subject_is_refused(tmp_path, monkeypatch):
    import lipgen.dataset.generate as gen
    from lipgen.rig.camera import MirrorRig, default_rig

    def far_mirror(w, h):
        rig = default_rig(w, h)
        return MirrorRig(rig.camera, rig.mirror_normal, rig.mirror_offset - 150.0)

    monkeypatch.setattr(gen, "default_rig", far_mirror)
    with pytest.raises(ValueError, match="mirror plane .* does not show the subject's marks"):
        gen.generate(tmp_path / "far", GenerateSettings(frames=3, size=(160, 120), calib_frames=0),
                     progress=False)
    assert not (tmp_path / "far").exists()


def test_manifest_validation_names_the_problem(reference):
    m = json.loads((reference / "manifest.json").read_text())
    validate_manifest(m)
    for change, match in (({"schema_version": 99}, "schema version 99"), ({"format": "x"}, "format"),
                          ({"frames": m["frames"][:-1]}, "frame list"), ({"convention": "opengl"}, "opencv")):
        with pytest.raises(DatasetError, match=match):
            validate_manifest({**m, **change})
    bad = dict(m)
    del bad["rig"]
    with pytest.raises(DatasetError, match="lacks"):
        validate_manifest(bad)
    with pytest.raises(DatasetError, match="no manifest"):
        Dataset(reference / "raw")


def test_generate_help_explains(capsys):
    with pytest.raises(SystemExit):
        main(["generate", "--help"])
    text = capsys.readouterr().out
    assert "--resume" in text and "--workers" in text and "viseme" in text
    assert os.environ.get("PYOPENGL_PLATFORM", "egl")


def test_depth_and_masks_agree_with_the_truth(reference, tmp_path):
    from lipgen.dataset.generate import generate

    s = GenerateSettings(frames=3, seed=2, size=(320, 240), calib_frames=0, dot_diameter=3.0,
                         depth=True, masks=True)
    ds = Dataset(generate(tmp_path / "ds", s, progress=False))
    legend = ds.manifest["mask_labels"]
    assert legend["0"] == "background" and legend[str(10 + len(ds.marks) - 1)] == "dot:nose"
    checked, dz = 0, []
    for i, fr in enumerate(ds):
        depth, mask = ds.depth(i), ds.mask(i)
        assert depth.shape == mask.shape == fr.image.shape[:2] and depth.dtype == np.float32
        # depth and labels are separate renders: they may disagree only on silhouette pixels
        disagree = np.isfinite(depth) != (mask > 0)
        assert disagree.mean() < 0.01 and (mask > 0).mean() > 0.2
        for v in range(len(VIEWS)):
            for k in np.flatnonzero(fr.visible[v] & (fr.dot_visible_fraction[v] == 1)):
                col, row = np.round(fr.uv_raw[v][k]).astype(int)
                assert mask[row, col] == 10 + k, (i, VIEWS[v], ds.marks[k])
                dz.append(depth[row, col] - fr.depth[v][k])
                checked += 1
    assert checked >= 40
    # mm: the depth drawn at the mark's nearest pixel centre against the mark's own depth; they
    # differ by the surface's slope over up to half a pixel (~0.4 mm here), steep at the corners
    print(f"depth at marks: median {np.median(np.abs(dz)):.3f} mm, max {np.abs(dz).max():.3f} mm")
    assert np.median(np.abs(dz)) < 0.5 and np.abs(dz).max() < 3.0
    with pytest.raises(DatasetError, match="--depth"):
        Dataset(reference).depth(0)


def test_training_displacements_are_the_truth_and_need_it(reference, tmp_path):
    import shutil

    from lipgen.blender.training import dataset_displacements

    ds = Dataset(reference)
    n, topo = ds.mesh.n_nodes, ds.mesh.topology_id
    X = dataset_displacements(reference, n, topo)
    assert X.shape == (len(ds), n, 3)
    np.testing.assert_array_equal(X[4], ds[4].truth["vertices"][:n] - ds.mesh.vertices[:n])
    copy = tmp_path / "ds"
    shutil.copytree(reference, copy)
    Dataset(copy).file(ds.manifest["frames"][0]["truth"]).unlink()
    with pytest.raises(DatasetError, match="no ground truth.*true motion"):
        dataset_displacements(copy, n, topo)
