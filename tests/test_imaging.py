"""Frame formation under ImageConditions: sensor, lens blur, mirror, presets, determinism."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lipgen.dataset.film import exposure_offsets, realize, rig_for, sub_frame_states
from lipgen.dataset.layout import GenerateSettings
from lipgen.dataset.presets import PRESETS
from lipgen.rig.camera import default_rig
from lipgen.rig.conditions import ImageConditions
from lipgen.rig.imaging import FrameFormer, on_mirror, srgb_decode, srgb_encode

cv2 = pytest.importorskip("cv2")
PLAIN = ImageConditions(read_noise=0.0, codec="png")


def _views(rig, value):
    return [np.full((c.height, c.width, 3), value, np.uint8) for c in rig.views]


def test_srgb_tables_round_trip_every_grey_level():
    levels = np.arange(256, dtype=np.uint8)
    np.testing.assert_array_equal(srgb_encode(srgb_decode(levels)), levels)
    assert abs(srgb_decode(np.uint8(188)) - 0.5) < 0.01  # sRGB 188 is half the light


def test_ideal_conditions_reproduce_the_views_exactly():
    rig = default_rig(160, 120)
    rng = np.random.default_rng(0)
    views = [rng.integers(0, 256, (c.height, c.width, 3), dtype=np.uint8) for c in rig.views]
    former = FrameFormer(rig, replace(PLAIN, mirror_reflectance=1.0))
    out = former.form([tuple(views)], rng)
    np.testing.assert_array_equal(out, rig.compose(*views))


def test_shot_and_read_noise_have_the_modelled_variance():
    rig = default_rig(320, 240)
    c = replace(PLAIN, full_well=5000.0, read_noise=2.0, mirror_reflectance=1.0)
    former = FrameFormer(rig, c)
    lin = np.full((240, 320, 3), 0.2, np.float32)
    img = former.sensor(lin, np.random.default_rng(1))
    measured = srgb_decode(img).std()
    expected = np.sqrt(0.2 / 5000 + (2.0 / 255) ** 2)
    assert abs(measured / expected - 1) < 0.05, (measured, expected)
    with pytest.raises(ValueError, match="read_noise must be in"):
        ImageConditions(read_noise=80)
    with pytest.raises(ValueError, match="exposure must be in"):
        ImageConditions(exposure=0.0)
    with pytest.raises(ValueError, match="codec must be one of"):
        ImageConditions(codec="webp")


def test_bayer_demosaicing_keeps_flat_colours_and_jpeg_stays_close():
    rig = default_rig(160, 120)
    colour = np.array([200, 120, 60], np.uint8)
    views = [np.broadcast_to(colour, (c.height, c.width, 3)).copy() for c in rig.views]
    former = FrameFormer(rig, replace(PLAIN, bayer=True, mirror_reflectance=1.0))
    out = former.form([tuple(views)], np.random.default_rng(0))
    np.testing.assert_array_equal(out[4:-4, 4:-4], np.broadcast_to(colour, out[4:-4, 4:-4].shape))
    jpeg = FrameFormer(rig, replace(PLAIN, codec="jpeg", jpeg_quality=85, mirror_reflectance=1.0))
    out = jpeg.form([tuple(views)], np.random.default_rng(0))
    assert np.abs(out.astype(int) - colour).max() <= 3


def test_defocus_follows_the_thin_lens_and_keeps_light():
    c = ImageConditions(focus_mm=340.0, aperture_px=12.0)
    assert c.defocus_diameter(340.0) == 0
    assert c.defocus_diameter(400.0) == pytest.approx(12.0 * 60 / 400)
    rig = default_rig(320, 240)
    former = FrameFormer(rig, replace(c, mirror_reflectance=1.0))
    assert former.kernels[0] is not None and former.kernels[0].sum() == pytest.approx(1.0)
    # the mirror view is farther from the focus than the direct one: more blur
    assert former.kernels[0].shape[0] >= (1 if former.kernels[1] is None else former.kernels[1].shape[0])


def test_mirror_tint_ghost_and_edge():
    rig = default_rig(320, 240)
    c = replace(PLAIN, mirror_reflectance=0.85, mirror_tint=(0.9, 1.0, 0.95), ghost=0.04, glass_mm=3.0,
                mirror_extent_mm=(40.0, 40.0))
    former = FrameFormer(rig, c)
    assert np.linalg.norm(former.ghost_shift) > 0.5  # 3 mm of glass at 400 mm: about a pixel
    assert former.mirror_mask.any() and not former.mirror_mask.all()  # the edge is in view
    views = _views(rig, 188)
    virt, real = former.views([tuple(views)])
    inside = former.mirror_mask[..., 0]
    lin = srgb_decode(np.uint8(188))
    tint = 0.85 * np.array([0.9, 1.0, 0.95])
    expected = lin * (tint * 0.96 ** 2 + 0.04)
    np.testing.assert_allclose(virt[inside].mean(axis=0), expected, rtol=1e-3)
    assert virt[~inside].max() < 0.05  # the dark room beyond the edge
    np.testing.assert_allclose(real, lin, rtol=1e-6)
    target = np.array([[0.0, 5.0, 0.0]])
    assert on_mirror(rig, (40.0, 40.0), target).all() and not on_mirror(rig, (1.0, 1.0), target + 30).any()


def test_motion_blur_instants_and_lighting_are_seeded():
    hard = PRESETS["hard"].image.conditions
    step = hard.blur_step_px
    assert len(exposure_offsets(hard, 0.99 * step)) == 1
    off = exposure_offsets(hard, 1.25 * step)  # 1 + ceil(1.25) instants, at most 2 px apart
    assert len(off) == 3 and off[0] == -hard.shutter / 2 and off[-1] == hard.shutter / 2
    assert len(exposure_offsets(hard, 100.0)) == hard.blur_samples
    one_px = replace(hard, blur_step_px=1.0)  # the default preset's spacing: 1 + ceil(2.5) instants
    assert len(exposure_offsets(one_px, 2.5)) == 4 == len(exposure_offsets(hard, 2.5, step_px=1.0))
    assert PRESETS["default"].image.conditions.blur_step_px == 1.0
    V = np.arange(3 * 4 * 3, dtype=float).reshape(3, 4, 3)
    P = np.stack([np.eye(4)] * 3)
    (Va, _), (Vb, _) = sub_frame_states(V, P, 1, np.array([-0.25, 0.5]))
    np.testing.assert_allclose(Va, 0.75 * V[1] + 0.25 * V[0])
    np.testing.assert_allclose(Vb, 0.5 * V[1] + 0.5 * V[2])
    a, b = realize(hard, 7), realize(hard, 7)
    assert a == b and realize(hard, 8) != a
    assert realize(ImageConditions(), 7)["lights"] == realize(ImageConditions(), 8)["lights"]


def test_presets_and_settings_round_trip():
    assert GenerateSettings.from_preset("easy") == GenerateSettings()
    hard = GenerateSettings.from_preset("hard", frames=3)
    assert GenerateSettings.from_dict(hard.to_dict()) == hard
    assert rig_for(hard.size, hard.conditions).camera.dist is not None
    with pytest.raises(ValueError, match="unknown preset 'medium'"):
        GenerateSettings.from_preset("medium")


def _two_hard_frames_twice(tmp_path, s):
    """Generate ``s`` (2 frames, h264) twice: the same bytes, a lens and lighting in the manifest,
    the exposure's truth, and a video that reads back as the frames. Returns (folder, Dataset)."""
    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import Dataset
    from lipgen.dataset.video import read_video_frames

    a, b = generate(tmp_path / "a", s, progress=False), generate(tmp_path / "b", s, progress=False)
    files = sorted(p.relative_to(a) for p in Path(a).rglob("*") if p.is_file())
    assert files and all((Path(a) / f).read_bytes() == (Path(b) / f).read_bytes() for f in files)
    ds = Dataset(a)
    assert ds.rig.camera.dist is not None and "lighting" in ds.manifest
    assert ds[1].truth["uv_exposure"].shape == (2, 2, 17, 2)
    video = list(read_video_frames(Path(a) / ds.manifest["video"]["file"]))
    assert len(video) == 2 and np.abs(video[1].astype(int) - ds[1].image).mean() < 4
    return a, ds


@pytest.mark.render
def test_hard_image_conditions_repeat_their_bytes_on_small_frames(tmp_path):
    """The hard preset's frame formation (lens, lighting, motion blur, sensor, h264 video) gives the
    same files twice, on two small frames with the linear truth (the layered truth physics, 1.3 s a
    frame, is the full test's, in the slow set)."""
    pytest.importorskip("pyrender")

    s = GenerateSettings.from_preset("hard", frames=2, seed=2, size=(160, 120), calib_frames=0,
                                     script="AA:0.1 OO:0.1")
    s = replace(s, conditions=replace(s.conditions, video_codec="h264"), truth_physics="linear")
    _two_hard_frames_twice(tmp_path, s)


@pytest.mark.slow(cover="tests/test_imaging.py::test_hard_image_conditions_repeat_their_bytes_on_small_frames")
@pytest.mark.render
def test_hard_frames_are_deterministic_and_keep_their_truth(tmp_path):
    pytest.importorskip("pyrender")
    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import Dataset

    # two frames: each costs about 1.3 s of the layered truth physics, and frame 1 moves
    s = GenerateSettings.from_preset("hard", frames=2, seed=2, size=(320, 240), calib_frames=0,
                                     script="AA:0.1 OO:0.1")
    s = replace(s, conditions=replace(s.conditions, video_codec="h264"))
    a, ds = _two_hard_frames_twice(tmp_path, s)
    # the picture of a hard frame beside an easy one
    from lipgen.cli import main
    from lipgen.dataset.pictures import preset_of

    # the easy side with the linear truth: preset_of and `show --beside` read the image conditions
    # and the frames, not the truth's physics (the layered one would be simulated a third time)
    easy_settings = replace(s, conditions=ImageConditions(), noise=1.0, truth_physics="linear")
    easy = generate(tmp_path / "e", easy_settings, progress=False)
    assert preset_of(Dataset(easy)) == "easy" and preset_of(ds) == "custom"  # hard + video
    picture = tmp_path / "p.png"
    assert main(["show", str(easy), "--beside", str(a), "--frame", "1", "--out", str(picture)]) == 0
    assert picture.stat().st_size > 10_000
    # the scene of a real recording is recorded, and the report's picture beside the easy preset
    from lipgen.dataset.pictures import easy_twin, save_beside_easy

    scene = ds.manifest["scene"]
    assert scene["head"]["fold_depth"] > 0 and "lower_teeth" in scene["mouth"] and scene["ink"]["smudge"] > 0
    twin = easy_twin(ds, 1)
    assert twin.shape == ds[1].image.shape and np.abs(twin.astype(int) - ds[1].image).mean() > 1
    assert save_beside_easy(ds, 1, tmp_path / "b.png").stat().st_size > 10_000


def test_video_round_trip_keeps_count_and_order(tmp_path):
    pytest.importorskip("imageio_ffmpeg")
    from lipgen.dataset.video import read_video_frames, write_video

    frames = []
    for k in range(12):  # frame k carries its number as a bright block at column 8 k
        f = np.full((48, 128, 3), 30, np.uint8)
        f[8:40, 8 * k:8 * k + 8] = 230
        frames.append(f)
    path = write_video(tmp_path / "v.mp4", frames, fps=30.0, crf=18)
    back = list(read_video_frames(path))
    assert len(back) == len(frames)
    for k, f in enumerate(back):
        assert int(np.argmax(f[24, :, 1].reshape(16, 8).mean(axis=1))) == k
        assert np.abs(f.astype(int) - frames[k]).mean() < 3
    again = write_video(tmp_path / "w.mp4", frames, fps=30.0, crf=18)
    assert again.read_bytes() == path.read_bytes()  # one x264 thread: the same bytes


def test_bad_video_and_preset_requests_write_nothing(tmp_path):
    from lipgen.cli import main

    with pytest.raises(ValueError, match="unknown video codec 'vp9'"):
        ImageConditions(video_codec="vp9")
    for argv in (["--preset", "medium"], ["--video", "vp9"]):
        try:
            code = main(["generate", "--frames", "2", "--out", str(tmp_path / "x"), *argv])
        except SystemExit as exc:
            code = exc.code
        assert code != 0
        assert not (tmp_path / "x").exists()
