"""Reconstruction of data without truth (a user's recording), and no silent loss of markers.

One small dataset (480x360, 8 frames, 5 calibration frames) is rendered once for the module;
the tests work on copies of it: with the truth removed, with a marker's dot erased, as a video.
"""

import json
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


@pytest.fixture(scope="module")
def bare(dataset, tmp_path_factory):
    """The dataset without its truth, and its reconstruction by ``lipgen reconstruct`` (one run,
    shared by the two tests below)."""
    tmp = tmp_path_factory.mktemp("bare")
    path, rec = _without_truth(dataset, tmp), tmp / "r.npz"
    assert main(["reconstruct", str(path), "--out", str(rec), "--no-progress", "--allow-missing"]) == 0
    return path, rec


def test_a_dataset_without_truth_reconstructs_the_same(dataset, recon, bare):
    from lipgen.dataset.layout import Dataset
    from lipgen.recon.pipeline import Reconstruction

    ds = Dataset(bare[0])
    assert not ds.has_truth and Dataset(dataset).has_truth
    assert ds[0].truth == {} == ds.truth(0) and ds.missing(truth=False) == [] and len(ds.missing()) == FRAMES
    again = Reconstruction.load(bare[1])
    # the normalisation's reference frame is a training frame (the default held-out tail is 2)
    assert again.info["normalisation"]["reference_frame"] < FRAMES - 2
    for name in ("uv", "lab_points", "markers", "fields"):
        a, b = getattr(recon, name), getattr(again, name)
        assert np.array_equal(np.isnan(a), np.isnan(b)), name
        np.testing.assert_allclose(b, a, atol=1e-6, rtol=0, equal_nan=True, err_msg=name)


def test_train_nrsfm_and_show_work_without_truth_and_evaluate_says_it_needs_it(tmp_path, bare):
    bare, rec = bare
    model, rep = tmp_path / "m.npz", tmp_path / "rep"
    assert main(["train", str(rec), "--out", str(model), "--modes", "2", "--test-frames", "2"]) == 0
    assert main(["nrsfm", str(rec), "--k", "1", "--out", str(tmp_path / "shapes.npz")]) == 0
    pic = tmp_path / "f.png"
    assert main(["show", str(bare), "--frame", "1", "--recon", str(rec), "--out", str(pic)]) == 0
    assert pic.stat().st_size > 1000
    with pytest.raises(DatasetError, match="no ground truth.*lipgen evaluate"):
        main(["-vv", "evaluate", str(bare), "--model", str(model), "--recon", str(rec), "--out", str(rep)])
    assert not rep.exists(), "nothing is written when the truth is missing"


def _erase_marker(dataset, tmp_path, name, view=1):
    """A copy of the dataset with mark ``name``'s ink dot painted over in ``view`` in every frame."""
    from PIL import Image

    from lipgen.dataset.layout import Dataset

    dst = tmp_path / "erased"
    shutil.copytree(dataset, dst)
    data = Dataset(dst)
    mark = data.marks.index(name)
    for f in range(len(data)):
        png = dst / "raw" / f"{f:06d}.png"
        img = np.asarray(Image.open(png).convert("RGB")).copy()
        u, v = np.round(data[f].truth["uv_raw"][view, mark]).astype(int)
        patch = img[v - 12:v + 13, u - 12:u + 13]
        ring = np.concatenate([patch[0], patch[-1], patch[:, 0], patch[:, -1]])
        img[v - 4:v + 5, u - 4:u + 5] = np.median(ring, axis=0).astype(np.uint8)
        Image.fromarray(img).save(png)
    return dst


def test_a_marker_never_seen_is_named_exits_3_and_evaluate_still_reports(tmp_path, dataset, capsys):
    from lipgen.commands.reconstruct import MISSING_STATUS

    ds = _erase_marker(dataset, tmp_path, "lower_left")
    rec, model, rep = tmp_path / "r.npz", tmp_path / "m.npz", tmp_path / "rep"
    assert main(["reconstruct", str(ds), "--out", str(rec), "--no-progress"]) == MISSING_STATUS == 3
    err = capsys.readouterr().err
    assert "never tracked in the real view: lower_left: no dot found" in err
    assert "never accepted: lower_left: never tracked in the real view (no dot found" in err
    assert "never accepted in any frame: lower_left" in err and "--allow-missing" in err
    line = next(ln for ln in err.splitlines() if ln.strip().startswith("lower_left "))
    assert "0 /   0 /   8 /   0 (0, 8)" in line, line          # accepted / rejected / unpaired / lost
    assert main(["reconstruct", str(ds), "--out", str(rec), "--no-progress", "--allow-missing",
                 "--force"]) == 0
    assert main(["train", str(rec), "--out", str(model), "--modes", "2", "--test-frames", "2"]) == 0
    assert main(["evaluate", str(ds), "--model", str(model), "--recon", str(rec), "--out", str(rep),
                 "--test-frames", "2"]) == 0
    text = (rep / "report.md").read_text()
    assert "lower_left in the real view: no dot found" in text
    assert "**Never accepted**" in text
    assert "- lower_left: never tracked in the real view (no dot found" in text
    nrsfm = text[text.index("## Non-rigid SfM on one view"):]
    assert "Left out of the tracked run" in nrsfm and "lower_left (0 frames)" in nrsfm
    # 8 frames are too few for the factorisation: the section says so instead of crashing
    assert "tracked by `track.py`" in nrsfm or "on the tracks: not computed" in nrsfm
    data = json.loads((rep / "report.json").read_text())
    real = data["tracking"]["real"]
    assert real["lost"] >= FRAMES and real["accepted"] + real["rejected"] + real["lost"] > 0


def _video(dataset, path, crf="12"):
    """The dataset's raw frames as an H.264 video (yuv420p, as cameras record)."""
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    from PIL import Image

    files = sorted((dataset / "raw").glob("*.png"))
    w, h = Image.open(files[0]).size
    writer = imageio_ffmpeg.write_frames(str(path), (w, h), fps=30, codec="libx264", macro_block_size=1,
                                         output_params=["-crf", crf], pix_fmt_out="yuv420p")
    writer.send(None)
    for f in files:
        writer.send(np.ascontiguousarray(np.asarray(Image.open(f).convert("RGB"))))
    writer.close()
    return path


@pytest.fixture(scope="module")
def video(dataset, tmp_path_factory):
    """The module's dataset as a video (encoded once: the tests below only read it)."""
    return _video(dataset, tmp_path_factory.mktemp("video") / "take.mp4")


def test_a_video_and_chessboard_photos_reconstruct_like_the_png_frames(tmp_path, dataset, recon, video,
                                                                       capsys):
    from lipgen.dataset.layout import Dataset

    rec = tmp_path / "rec"
    assert main(["recording", "init", str(video), "--calib", str(dataset / "calib"), "--out", str(rec),
                 "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "000004.png" in text and "mirror on the left" in text and "split column 320" in text
    ds = Dataset(rec)
    assert not ds.has_truth and len(ds) == FRAMES and ds.manifest["source"] == "recording"
    assert ds.rig.mirror_side == "left" and ds.rig.split == 320
    out = tmp_path / "r.npz"
    # H.264 (yuv420p) now and then costs a marker some frames, or all of them, and the RMS of the
    # differences is then a few wrong sightings': the share and the RMS move with the sensor noise's
    # realisation, not its law. Measured on this test's 8-frame datasets at seeds 5-19, with main's
    # float noise (16 realisations) and the integer noise of lipgen.rig.noise (15): share in both
    # 0.879-1.0 and RMS 0.11-1.05 px (main's float noise fails the old share > 0.97 / RMS < 0.3 px at
    # seeds 8, 14, 16 and with another realisation at seed 5; at seed 8 a marker is never accepted);
    # median 0.070-0.100 px and 90th percentile 0.17-0.26 px in every one.
    assert main(["reconstruct", str(rec), "--out", str(out), "--no-progress", "--allow-missing"]) == 0
    from lipgen.recon.pipeline import Reconstruction

    got = Reconstruction.load(out)
    d = np.linalg.norm(got.uv - recon.uv, axis=-1)
    both = np.isfinite(d)
    assert both.mean() > 0.85
    assert np.median(d[both]) < 0.15, "the video's tracks are those of the PNG frames"
    assert np.percentile(d[both], 90) < 0.35
    # Issue 16's target: within 0.3 px RMS over the sightings both runs accept. This clip (seed 5)
    # was 1.42 px before the identity re-check (a lure 9 px along the epipolar line matched in the
    # video's first frame, mouth open); 0.17 px with it (recon/recheck.py).
    acc = got.visible & recon.visible
    rms = np.sqrt(np.mean(np.concatenate([d[v][:, :acc.shape[1]][acc] for v in range(2)]) ** 2))
    assert rms < 0.3, f"{rms:.2f} px RMS between the video's and the PNG frames' accepted sightings"
    per_image = got.calibration.per_image
    assert len(per_image) == 5 and all(p["real"] < 0.5 and p["virtual"] < 0.5 for p in per_image)


def test_a_folder_of_frames_reconstructs_directly_like_the_dataset(tmp_path, dataset, recon, capsys):
    """``reconstruct FRAMES --calib PHOTOS``: the recording is built beside --out, and the frames are
    the dataset's own pixels, so the tracks are the dataset's (to the runs' own 1e-6 px)."""
    from lipgen.dataset.layout import Dataset
    from lipgen.recon.pipeline import Reconstruction

    frames = tmp_path / "frames"
    shutil.copytree(dataset / "raw", frames)
    out = tmp_path / "take.npz"
    calib = str(dataset / "calib")
    assert main(["reconstruct", str(frames), "--calib", calib, "--fps", "25", "--out", str(out),
                 "--no-progress", "--allow-missing"]) == 0
    assert "mirror on the left" in capsys.readouterr().out
    rec = Dataset(tmp_path / "take_recording")
    assert not rec.has_truth and len(rec) == FRAMES and rec.manifest["settings"]["fps"] == 25
    got = Reconstruction.load(out)
    assert np.nanmax(np.abs(got.uv - recon.uv)) < 1e-6
    assert np.array_equal(np.isnan(got.uv), np.isnan(recon.uv))
    # the recording is kept; a second run refuses to replace it (or --out) without --force
    capsys.readouterr()
    assert main(["reconstruct", str(frames), "--calib", calib, "--out", str(tmp_path / "b.npz"),
                 "--recording", str(tmp_path / "take_recording")]) == 1
    assert "take_recording exists and is not empty" in capsys.readouterr().err
    assert main(["reconstruct", str(frames), "--out", str(tmp_path / "c.npz")]) == 1
    assert "frames is not a dataset folder (no manifest.json)" in capsys.readouterr().err
    assert not (tmp_path / "b.npz").exists() and not (tmp_path / "c.npz").exists()


def test_a_frame_folder_of_mixed_sizes_is_named_and_nothing_is_written(tmp_path, dataset, capsys):
    from PIL import Image

    frames = tmp_path / "frames"
    shutil.copytree(dataset / "raw", frames)
    Image.open(frames / "000003.png").resize((320, 240)).save(frames / "000003.png")
    assert main(["reconstruct", str(frames), "--calib", str(dataset / "calib"), "--out",
                 str(tmp_path / "r.npz")]) == 1
    assert "000003.png is 320x240 but 000000.png is 640x480" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frames"], "nothing written"


def test_bad_recording_inputs_are_named_and_nothing_is_written(tmp_path, dataset, video):
    from PIL import Image

    from lipgen.recon.recording import init_recording

    out = tmp_path / "rec"
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(b"this is not a video" * 100)
    with pytest.raises(DatasetError, match="junk.mp4 cannot be decoded"):
        init_recording(junk, dataset / "calib", out)
    with pytest.raises(DatasetError, match="no calibration folder"):
        init_recording(video, tmp_path / "nowhere", out)
    (tmp_path / "empty").mkdir()
    with pytest.raises(DatasetError, match="empty holds no calibration images"):
        init_recording(video, tmp_path / "empty", out)
    few = tmp_path / "few"
    few.mkdir()
    for f in sorted((dataset / "calib").glob("*.png"))[:3]:
        shutil.copy(f, few / f.name)
    with pytest.raises(DatasetError, match="holds 3 calibration image"):
        init_recording(video, few, out)
    faces = tmp_path / "faces"          # photos without a chessboard
    faces.mkdir()
    for f in sorted((dataset / "raw").glob("*.png"))[:4]:
        shutil.copy(f, faces / f.name)
    with pytest.raises(DatasetError, match="board .* was found whole in"):
        init_recording(video, faces, out, mirror_side="left", split=320)
    mixed = tmp_path / "mixed"
    shutil.copytree(dataset / "calib", mixed)
    Image.open(mixed / "000002.png").resize((320, 240)).save(mixed / "000002.png")
    with pytest.raises(DatasetError, match="000002.png is 320x240 but the recording's frames are 640x480"):
        init_recording(video, mixed, out)
    assert not out.exists() and not list(tmp_path.glob(".rec.part*")), "nothing written"
    # a recording without its calibration images is refused by reconstruct, naming them
    init_recording(video, dataset / "calib", out, mirror_side="left", split=320)
    (out / "calib" / "000001.png").unlink()
    with pytest.raises(DatasetError, match=r"no calibration images \(calib/000001.png missing\)"):
        reconstruct_dataset(out)
    with pytest.raises(FileExistsError, match="--force"):
        init_recording(video, dataset / "calib", out)


def test_calibration_reports_each_image_and_drops_an_outlier(dataset, monkeypatch, caplog):
    from PIL import Image

    import lipgen.recon.calibrate as calibrate
    from lipgen.dataset.layout import Dataset
    from lipgen.recon.calibcache import calibrated

    ds = Dataset(dataset)
    images = [np.asarray(Image.open(p).convert("RGB")) for p in sorted((dataset / "calib").glob("*.png"))]
    # calibrate_rig's result for these images, as reconstruct_dataset computed it for the module's
    # `recon` (reused when this worker made it: tests/test_calibcache.py checks the keying)
    clean = calibrated(images, ds.rig, ds.board())
    assert clean.dropped == () and len(clean.per_image) == 5
    found, calls = calibrate.find_corners, []

    def blurred(image, board):      # image 3's direct view: corners off by ~2 px (a blurred board)
        uv = found(image, board)
        calls.append(1)
        if len(calls) == 8 and uv is not None:
            uv = uv + np.random.default_rng(0).normal(0, 2.0, uv.shape)
        return uv

    monkeypatch.setattr(calibrate, "find_corners", blurred)
    cal = calibrate.calibrate_rig(images, ds.rig, ds.board())
    assert [(d["image"], d["view"]) for d in cal.dropped] == [(3, "real")]
    assert "calibration image 3: the real view's board reprojects" in caplog.text
    assert cal.per_image[3]["real"] is None and cal.per_image[3]["virtual"] < 0.5
    assert cal.rms["all"] < 1.5 * clean.rms["all"]


def test_at_320x240_the_midline_is_tracked_or_named_with_status_3(tmp_path, capsys):
    """Regression: at 320x240 the midline markers' dots merge; they are tracked (two-dot model)
    or named on stderr, and a whole marker lost gives exit status 3: never a silent 0."""
    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import GenerateSettings
    from lipgen.rig.render import import_pyrender

    try:
        import_pyrender()
    except Exception as exc:  # no GL here: the rendering tests cannot run
        pytest.skip(f"no offscreen rendering: {exc}")
    ds = generate(tmp_path / "small", GenerateSettings(frames=6, seed=5, size=(320, 240), calib_frames=8),
                  progress=False)
    status = main(["reconstruct", str(ds), "--out", str(tmp_path / "r.npz"), "--no-progress"])
    err = capsys.readouterr().err
    from lipgen.recon.pipeline import Reconstruction

    account = Reconstruction.load(tmp_path / "r.npz").info["sightings"]
    for n in account["never_tracked"]:
        assert f"never tracked in the {n['view']} view: {n['mark']}: " in err
    missing = account["missing"]
    assert sorted(missing) == sorted(m for m, c in account["per_mark"].items() if c["accepted"] == 0)
    assert status == (3 if missing else 0)
    if missing:
        assert "never accepted in any frame: " + ", ".join(missing) in err
    for mark in ("upper_mid", "bow_dip", "lower_mid", "lower_border_mid"):
        assert account["per_mark"][mark]["accepted"] > 0 or mark in missing
