"""Lip sync from speech: audio reading, phones, the duration model, viseme dynamics (no
pocketsphinx or espeak-ng needed here; see test_speech_sphinx.py for those)."""

from __future__ import annotations

import logging
import struct

import numpy as np
import pytest

from lipgen.speech.audio import RATE, AudioError, NoSpeechError, as_audio, check_speech, read_wav
from lipgen.speech.phones import KLATT_MS, PhoneTrack, TextError, text_phones, words_of
from lipgen.speech.score import edit_alignment, speech_shaped_noise
from lipgen.speech.visemes import TAU, activations, phone_targets
from lipgen.subject.activation import ACTIONS, VISEMES, action_index


def _wav(path, data: bytes, rate: int, channels: int, bits: int, tag: int = 1) -> None:
    block = channels * bits // 8
    fmt = struct.pack("<HHIIHH", tag, channels, rate, rate * block, block, bits)
    path.write_bytes(b"RIFF" + struct.pack("<I", 36 + len(data)) + b"WAVE" + b"fmt "
                     + struct.pack("<I", 16) + fmt + b"data" + struct.pack("<I", len(data)) + data)


def _tone(rate: int, seconds: float = 0.5, hz: float = 440.0, amp: float = 0.5) -> np.ndarray:
    return amp * np.sin(2 * np.pi * hz * np.arange(int(rate * seconds)) / rate)


def _peak_hz(x: np.ndarray) -> float:
    spec = np.abs(np.fft.rfft(x * np.hanning(len(x))))
    return float(np.argmax(spec) * RATE / len(x))


@pytest.mark.parametrize("bits,kind,tag", [(8, "u1", 1), (16, "<i2", 1), (32, "<i4", 1), (32, "<f4", 3),
                                           (64, "<f8", 3), (24, None, 1)])
def test_read_wav_formats_resampled_to_16k(tmp_path, caplog, bits, kind, tag):
    x = _tone(44100)
    stereo = np.stack([x, x], axis=1)  # identical channels: the mono mix is the tone
    if kind is None:  # 24-bit little-endian integers
        q = np.round(stereo * (2**23 - 1)).astype(np.int32).ravel()
        data = np.stack([q & 255, (q >> 8) & 255, (q >> 16) & 255], axis=1).astype(np.uint8).tobytes()
    elif kind == "u1":
        data = np.round(stereo * 127 + 128).astype(np.uint8).tobytes()
    elif kind.startswith("<i"):
        data = np.round(stereo * (2 ** (bits - 1) - 1)).astype(kind).tobytes()
    else:
        data = stereo.astype(kind).tobytes()
    _wav(tmp_path / "a.wav", data, 44100, 2, bits, tag)
    with caplog.at_level(logging.INFO, logger="lipgen.speech.audio"):
        audio = read_wav(tmp_path / "a.wav")
    assert audio.rate == RATE and audio.source_rate == 44100
    assert abs(audio.duration - 0.5) < 1e-3
    assert abs(_peak_hz(audio.samples) - 440.0) < 4.0
    mid = audio.samples[1000:-1000]
    assert abs(np.abs(mid).max() - 0.5) < 0.02
    assert "resampling 44100 Hz to 16000 Hz" in caplog.text and "mixing 2 channels" in caplog.text


def test_read_wav_bad_files(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_wav(tmp_path / "missing.wav")
    (tmp_path / "text.wav").write_text("not audio at all")
    with pytest.raises(AudioError, match="not a WAV file"):
        read_wav(tmp_path / "text.wav")
    _wav(tmp_path / "adpcm.wav", b"\0" * 400, 16000, 1, 4, tag=2)
    with pytest.raises(AudioError, match="inconsistent|unsupported"):
        read_wav(tmp_path / "adpcm.wav")
    _wav(tmp_path / "alaw.wav", b"\0" * 400, 16000, 1, 8, tag=6)
    with pytest.raises(AudioError, match="unsupported WAV sample format"):
        read_wav(tmp_path / "alaw.wav")
    _wav(tmp_path / "empty.wav", b"", 16000, 1, 16)
    with pytest.raises(AudioError, match="no samples"):
        read_wav(tmp_path / "empty.wav")


def test_silence_is_no_speech():
    with pytest.raises(NoSpeechError, match="no speech found"):
        check_speech(as_audio(np.zeros(16000), 16000))
    with pytest.raises(NoSpeechError, match="no speech found"):
        check_speech(as_audio(1e-5 * np.random.default_rng(0).normal(size=16000), 16000))
    check_speech(as_audio(_tone(16000), 16000))  # loud enough


def test_words_and_language_errors():
    assert words_of("Glue the sheet, to the dark-blue background!") == [
        ["glue", "the", "sheet"], ["to", "the", "dark-blue", "background"]]
    with pytest.raises(TextError, match="English text only.*CYRILLIC"):
        words_of("Здравствуйте, мир")
    with pytest.raises(ValueError, match="holds no words"):
        words_of("  ... ")
    lex = {"the": ("DH", "AH"), "cat": ("K", "AE", "T"), "sat": ("S", "AE", "T")}
    with pytest.raises(TextError, match="missing from the pronouncing dictionary: zorp"):
        text_phones("the cat zorp sat", lexicon=lex)
    with pytest.raises(TextError, match="does not look like English"):
        text_phones("le chat est sur la table", lexicon=lex)


def test_klatt_durations_closed_form():
    lex = {"bob": ("B", "AA", "B"), "a": ("AH",), "bobby": ("B", "AA", "B", "IY")}
    track = text_phones("bob", lexicon=lex)
    assert track.labels == ("SIL", "B", "AA", "B", "SIL")
    dur = (track.end - track.start) * 1000

    def klatt(p, f):
        inh, mn = KLATT_MS[p]
        return mn + (inh - mn) * f

    # B word-initial, AA clause-final (x1.4), final B non-initial (x0.85)
    assert np.allclose(dur[1:4], [klatt("B", 1.0), klatt("AA", 1.4), klatt("B", 0.85)])
    assert np.allclose(dur[[0, -1]], 300.0)
    # polysyllabic and non-final shortening; half the rate doubles every phone (pauses stay)
    two = text_phones("bobby", lexicon=lex)
    d2 = (two.end - two.start) * 1000
    assert np.isclose(d2[2], klatt("AA", 0.85 * 0.8)) and np.isclose(d2[4], klatt("IY", 1.4 * 0.8))
    slow = text_phones("bobby", rate=0.5, lexicon=lex)
    assert np.allclose((slow.end - slow.start)[1:-1], 2 * (two.end - two.start)[1:-1])
    assert np.allclose(two.start[1:], two.end[:-1])  # contiguous


def test_phone_track_checks():
    with pytest.raises(ValueError, match="unknown phone labels"):
        PhoneTrack(("XX",), [0.0], [1.0])
    with pytest.raises(ValueError, match="end > start"):
        PhoneTrack(("AA",), [1.0], [1.0])


def _track(items):
    labels = [p for p, _ in items]
    ends = np.cumsum([d for _, d in items])
    return PhoneTrack(tuple(labels), np.concatenate([[0.0], ends[:-1]]), ends)


def test_dynamics_step_response_is_critically_damped():
    """A long AA from rest: each action follows T (1 - (1 + t/tau) e^(-t/tau)) from its onset."""
    fps, lead = 1000.0, 0.0
    A = activations(_track([("AA", 1.0)]), fps=fps, lead=lead)
    t = np.arange(len(A)) / fps
    for action, target in VISEMES["AA"].items():
        tau = TAU[action]
        expected = target * (1 - (1 + t / tau) * np.exp(-t / tau))
        assert np.allclose(A[:, action_index(action)], expected, atol=1e-9)
    assert np.allclose(np.delete(A, [action_index(a) for a in VISEMES["AA"]], axis=1), 0.0)


def test_coarticulation_comes_from_the_dynamics():
    """A short M between vowels is not fully reached; a long one is; the lips start to close before
    the M's acoustic start (the lead), and an underspecified T keeps the lip actions moving."""
    press = action_index("lip_press")
    fps = 1000.0
    short = activations(_track([("AA", 0.3), ("M", 0.04), ("AA", 0.3)]), fps=fps)
    long = activations(_track([("AA", 0.3), ("M", 0.3), ("AA", 0.3)]), fps=fps)
    target = VISEMES["M"]["lip_press"]
    assert long[:, press].max() == pytest.approx(target, abs=1e-3)
    assert 0.3 * target < short[:, press].max() < 0.95 * target
    assert long[int(0.29 * fps), press] > 0.05  # anticipation: moving before the M sounds
    # UW then T: T sets only the jaw, so the pucker decays smoothly instead of jumping to 0
    pucker = action_index("pucker")
    T, _ = phone_targets(_track([("UW", 0.3), ("T", 0.1)]))
    assert np.isnan(T[1, pucker]) and T[1, action_index("jaw_open")] == VISEMES["L"]["jaw_open"]
    A = activations(_track([("UW", 0.3), ("T", 0.1), ("SIL", 0.3)]), fps=fps)
    during_t = A[int(0.27 * fps):int(0.36 * fps), pucker]
    assert during_t.min() > 0.8 * A[int(0.25 * fps), pucker]
    assert A.shape[1] == len(ACTIONS) and (A >= 0).all() and (A <= 1).all()


def test_edit_alignment_and_noise():
    d, pairs = edit_alignment(list("kitten"), list("sitting"))
    assert d == 3 and len(pairs) == 6
    audio = as_audio(_tone(16000, 1.0), 16000)
    noisy = speech_shaped_noise(audio, 10.0, seed=1)
    noise = noisy.samples - audio.samples
    assert 10 * np.log10(np.mean(audio.samples**2) / np.mean(noise**2)) == pytest.approx(10.0, abs=1e-6)
    assert abs(_peak_hz(noise) - 440.0) < 4.0  # shaped like the signal's spectrum


def test_resample_matches_scipy_polyphase():
    """The Fourier resampler against scipy's polyphase filter on a band-limited random signal."""
    from scipy.signal import resample_poly

    from lipgen.speech.audio import resample

    rng = np.random.default_rng(3)
    t = np.arange(44100) / 44100
    x = sum(rng.uniform(0.05, 0.2) * np.sin(2 * np.pi * f * t + rng.uniform(0, 6))
            for f in rng.uniform(50, 6000, 20))
    x *= np.hanning(len(x))  # quiet ends, as a clip of speech
    ours, ref = resample(x, 44100, 16000), resample_poly(x, 160, 441)
    assert ours.shape == ref.shape == (16000,)
    assert np.abs(ours - ref)[200:-200].max() < 2e-3 * np.abs(x).max()


def test_artist_markers_matched_and_fitted():
    """Markers of another mesh (shuffled, shifted, scaled) are matched to LipGen's by position, and
    the ridge fit at the markers recovers coefficients that made the marker motion."""
    from lipgen.blender.lipsync import marker_coefficients, match_markers
    from lipgen.mesh.procedural import lip_mesh

    lm = lip_mesh(1)
    P = lm.vertices[lm.markers]
    perm = np.random.default_rng(0).permutation(len(P))
    rig = 3.0 * P[perm] + [5.0, -2.0, 1.0]
    assert np.array_equal(match_markers(rig, None, P, lm.marker_names), perm)
    names = [lm.marker_names[i] for i in perm[:5]]
    assert np.array_equal(match_markers(rig[:5], names, P, lm.marker_names), perm[:5])
    with pytest.raises(ValueError, match="16 markers"):
        match_markers(rig[:5], None, P, lm.marker_names)
    rng = np.random.default_rng(1)
    comps, mean = rng.normal(size=(4, 30, 3)), rng.normal(size=(30, 3))
    markers = np.arange(0, 30, 2)
    coef = rng.normal(size=(6, 4))
    targets = mean[markers] + np.einsum("fk,kmi->fmi", coef, comps[:, markers])
    assert np.allclose(marker_coefficients(comps, mean, markers, targets, ridge=1e-12), coef, atol=1e-8)


def test_lexicon_lookup_equals_a_full_parse(tmp_path):
    from lipgen.speech.phones import pronunciations

    lines = ["'bout B AW T", "a AH", "a(2) EY", "a's EY Z", "abc EY B IY S IY", "zulu Z UW L UW",
             "b-52 B IY F IH F T IY T UW", "mcdonald M AH K D AA N AH L D"]
    path = tmp_path / "small.dict"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    full = {k: tuple(v.split()) for k, v in (line.split(" ", 1) for line in lines)}
    lex = pronunciations(path)
    for word in [*full, "ab", "zul", "zulus", "a(3)", "", "a b", "AH", "mcdonald's"]:
        assert (word in lex) == (word in full), word
        if word in full:
            assert lex[word] == full[word]
        else:
            with pytest.raises(KeyError):
                lex[word]
    assert dict(lex.items()) == full and len(lex) == len(full)
    # a dictionary out of letter order is read right too
    unordered = tmp_path / "unordered.dict"
    unordered.write_text("bee B IY\nant AE N T\nbat B AE T\nape EY P\n", encoding="utf-8")
    lex = pronunciations(unordered)
    assert lex["bat"] == ("B", "AE", "T") and lex["ape"] == ("EY", "P") and "bo" not in lex
