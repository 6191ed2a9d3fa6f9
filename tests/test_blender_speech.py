"""'Animate from Audio' in Blender (headless pip bpy): sliders keyed from speech, the sound in
the sequencer, undo; on LipGen's lips and on an artist's mesh with modes and markers."""

import pytest
from blender_session import bpy_available, shared_session

pytestmark = [pytest.mark.blender,
              pytest.mark.skipif(not bpy_available(), reason="needs the pip bpy module")]
pytest.importorskip("pocketsphinx", reason="pip install 'lipgen[speech]'")

MIXED_MM = 3e-5  # several float32 shape keys mixed (see test_blender_addon.py)
TEXT = "The small pup gnawed a hole in the sock."


@pytest.fixture(scope="module")
def speech(tmp_path_factory):
    from lipgen.speech import espeak
    from lipgen.speech.audio import write_wav

    if not espeak.available():
        pytest.skip("espeak-ng is not installed (apt-get install espeak-ng)")
    audio, _ = espeak.synthesize(TEXT)
    path = tmp_path_factory.mktemp("speech") / "pup.wav"
    write_wav(path, audio)
    return str(path)


@pytest.fixture(scope="module")
def blender():
    return shared_session()


def test_animate_from_audio_on_lips(blender, speech):
    out = blender.run("bpy_checks_speech:check_audio_on_lips", speech, TEXT)
    assert out["phone_source"] == "alignment" and out["frames"] > 40 and out["peak_mm"] > 2.0
    assert out["max_dev_mm"] < MIXED_MM, out
    assert out["strips"] == [("SOUND", 7, speech)]
    assert out["frame_end"] >= 7 + out["frames"] - 1
    assert out["strips_after_undo"] == 0 and out["action_after_undo"] is None
    assert "not found" in out["missing_file"]


def test_animate_from_audio_on_artist_mesh(blender, speech):
    out = blender.run("bpy_checks_speech:check_audio_on_artist_mesh", speech, TEXT)
    assert "markers" in out["refusal"]
    assert out["matched"] == list(range(16))  # every LipGen marker used once
    assert out["max_slider_dev"] < 1e-4 and out["moved_mm"] > 0.1
