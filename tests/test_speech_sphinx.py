"""Lip sync with PocketSphinx on eSpeak NG speech of known phone timings, the lipsync command and
its outputs (USD with audio, npz, csv), and a small run of the accuracy experiment."""

from __future__ import annotations

import logging

import numpy as np
import pytest

pytest.importorskip("pocketsphinx", reason="pip install 'lipgen[speech]' (pocketsphinx)")

from lipgen.cli import main  # noqa: E402
from lipgen.speech import espeak  # noqa: E402
from lipgen.speech.audio import NoSpeechError, as_audio, write_wav  # noqa: E402
from lipgen.speech.decode import align, phones_from_audio, recognize  # noqa: E402
from lipgen.speech.score import boundary_errors, viseme_agreement  # noqa: E402
from lipgen.subject.activation import ACTIONS  # noqa: E402

needs_espeak = pytest.mark.skipif(not espeak.available(), reason="espeak-ng is not installed "
                                  "(apt-get install espeak-ng, or `make espeak`)")
DEV = espeak.HARVARD[2]  # list 3: the development list (the test lists 1-2 are for the report)


@pytest.fixture(scope="module")
def spoken():
    if not espeak.available():
        pytest.skip("espeak-ng is not installed (apt-get install espeak-ng)")
    return [(text, *espeak.synthesize(text)) for text in DEV[:2]]


@needs_espeak
def test_forced_alignment_boundaries(spoken):
    errs, agree = [], []
    for text, audio, truth in spoken:
        track = align(audio, text)
        assert track.source == "alignment" and track.confidence > 0.15
        assert np.allclose(track.start[1:], track.end[:-1]) and track.end[-1] == pytest.approx(audio.duration,
                                                                                                 abs=0.011)
        err, same = boundary_errors(truth, track)
        assert same > 0.7
        errs.append(err)
        agree.append(viseme_agreement(truth, track))
    err = np.concatenate(errs)
    assert np.median(err) < 0.03 and np.percentile(err, 90) < 0.1
    assert min(agree) > 0.5


@needs_espeak
def test_lipsync_usdz_packages_the_audio(spoken, tmp_path, capsys):
    import zipfile

    pxr = pytest.importorskip("pxr", reason="pip install 'lipgen[usd]'")
    text, audio, _ = spoken[1]
    wav = tmp_path / "speech.wav"
    write_wav(wav, audio)
    for name in ("lips.usdz", "lips.usdc"):
        assert main(["lipsync", str(wav), "--text", text, "--start", "3", "--out", str(tmp_path / name)]) == 0
    with zipfile.ZipFile(tmp_path / "lips.usdz") as z:
        inside = z.namelist()
        assert inside[0].endswith(".usdc") and any(n.endswith(".wav") for n in inside)
        packed = next(n for n in inside if n.endswith(".wav"))
        assert z.read(packed) == wav.read_bytes()
    zipped, plain = (pxr.Usd.Stage.Open(str(tmp_path / n)) for n in ("lips.usdz", "lips.usdc"))
    sound = pxr.UsdMedia.SpatialAudio(zipped.GetPrimAtPath("/Lips/Speech"))
    assert sound.GetStartTimeAttr().Get().GetValue() == 3
    assert sound.GetFilePathAttr().Get().resolvedPath.endswith(f"lips.usdz[{packed}]")

    def weights(stage):
        anim = [p for p in stage.Traverse() if p.GetTypeName() == "SkelAnimation"][0]
        attr = anim.GetAttribute("blendShapeWeights")
        return np.array([attr.Get(t) for t in attr.GetTimeSamples()])

    assert np.array_equal(weights(zipped), weights(plain))
    # text alone: the package holds the stage only
    assert main(["lipsync", "--text", text, "--out", str(tmp_path / "text.usdz")]) == 0
    with zipfile.ZipFile(tmp_path / "text.usdz") as z:
        assert z.namelist() == ["lipsync.usdc"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lips.usdc", "lips.usdz", "speech.wav", "text.usdz"]


@needs_espeak
def test_reused_decoders_give_a_fresh_decoders_results(spoken):
    from lipgen.speech import decode

    def key(track):
        return track.labels, track.start.tolist(), track.end.tolist(), track.confidence

    (text_a, audio_a, _), (text_b, audio_b, _) = spoken
    decode._LOCAL.__dict__.pop("decoders", None)  # fresh decoders
    first = key(align(audio_a, text_a)), key(recognize(audio_a))
    align(audio_b, text_b), recognize(audio_b)  # other speech through the same decoders
    assert (key(align(audio_a, text_a)), key(recognize(audio_a))) == first
    assert (key(align(audio_a, text_a)), key(recognize(audio_a))) == first


@needs_espeak
def test_wrong_transcript_falls_back_to_recognition(spoken, caplog):
    _, audio, _ = spoken[0]
    with caplog.at_level(logging.WARNING, logger="lipgen.speech.decode"):
        track = phones_from_audio(audio, "we all went to the market on sunday morning")
    assert track.source == "recognition"
    assert "recognition instead" in caplog.text


def test_silence_has_no_speech():
    with pytest.raises(NoSpeechError, match="no speech found"):
        recognize(as_audio(np.zeros(16000), 16000))


@needs_espeak
def test_lipsync_command_usd_with_audio(spoken, tmp_path, capsys):
    pxr = pytest.importorskip("pxr", reason="pip install 'lipgen[usd]'")
    text, audio, _ = spoken[0]
    wav = tmp_path / "speech.wav"
    write_wav(wav, audio)
    out = tmp_path / "lips.usda"
    assert main(["lipsync", str(wav), "--text", text, "--start", "10", "--out", str(out)]) == 0
    assert "aligned to the transcript" in capsys.readouterr().out
    stage = pxr.Usd.Stage.Open(str(out))
    prim = stage.GetPrimAtPath("/Lips/Speech")
    sound = pxr.UsdMedia.SpatialAudio(prim)
    assert prim.IsValid() and prim.GetTypeName() == "SpatialAudio"
    assert sound.GetStartTimeAttr().Get().GetValue() == 10
    assert sound.GetEndTimeAttr().Get().GetValue() == pytest.approx(10 + audio.duration * 30, abs=1e-3)
    assert sound.GetFilePathAttr().Get().resolvedPath == str(wav.resolve())
    assert sound.GetAuralModeAttr().Get() == "nonSpatial"
    anim = [p for p in stage.Traverse() if p.GetTypeName() == "SkelAnimation"][0]
    times = anim.GetAttribute("blendShapeWeights").GetTimeSamples()
    assert times[0] == 10 and len(times) == int(np.ceil(audio.duration * 30)) + 1
    from lipgen.usd import validate

    assert not [i for i in validate(out) if i.is_error]
    # no overwrite without --force; a failing run writes nothing
    before = out.read_bytes()
    assert main(["lipsync", str(wav), "--out", str(out)]) == 1
    assert out.read_bytes() == before
    bad = tmp_path / "bad.wav"
    bad.write_text("nope")
    assert main(["lipsync", str(bad), "--out", str(tmp_path / "x.npz")]) == 1
    assert "not a WAV file" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.wav", "lips.usda", "speech.wav"]


def test_lipsync_text_only_npz_and_csv(tmp_path):
    text = "Glue the sheet to the dark blue background."
    out = tmp_path / "glue.npz"
    assert main(["lipsync", "--text", text, "--fps", "24", "--out", str(out)]) == 0
    with np.load(out) as z:
        coef, A, fps = z["coefficients"], z["activations"], float(z["fps"])
        phones, start = list(z["phones"]), z["phone_start"]
        assert str(z["phone_source"]) == "text"
    assert fps == 24 and coef.shape == (len(A), 10) and A.shape[1] == len(ACTIONS)
    assert phones[:4] == ["SIL", "G", "L", "UW"] and np.all(np.diff(start) > 0)
    assert np.ptp(coef, axis=0).max() > 1.0  # the lips move
    csv = tmp_path / "glue.csv"
    assert main(["lipsync", "--text", text, "--fps", "24", "--out", str(csv)]) == 0
    rows = csv.read_text().splitlines()
    assert rows[0].startswith("frame,time_s,mode00") and len(rows) == len(coef) + 1
    assert np.allclose([float(v) for v in rows[5].split(",")[2:]], coef[4], rtol=1e-5, atol=1e-5)
    assert main(["lipsync", "--text", "Bonjour à tous les élèves", "--out", str(tmp_path / "f.npz")]) == 1
    assert not (tmp_path / "f.npz").exists()


@needs_espeak
def test_experiment_small(tmp_path):
    from lipgen.experiments.lipsync import LipsyncSettings, run_lipsync_experiment

    report = run_lipsync_experiment(tmp_path, LipsyncSettings(lists=(3,), snr_db=(float("inf"), 10.0),
                                                              max_sentences=1))
    text = report.read_text()
    assert "boundary median ms" in text and (tmp_path / "list3.png").stat().st_size > 10_000
    import json

    summary = json.loads((tmp_path / "lipsync.json").read_text())["summary"]
    assert summary["inf"]["sentences"] == 1 and summary["inf"]["boundary_error_median_ms"] < 40


@needs_espeak
def test_generate_from_speech_stores_audio_and_phones(spoken, tmp_path):
    pytest.importorskip("pyrender", reason="pip install 'lipgen[render]'")
    import json

    from lipgen.dataset import Dataset
    from lipgen.speech.audio import read_wav
    from lipgen.speech.phones import PhoneTrack
    from lipgen.speech.visemes import activations

    text, audio, _ = spoken[0]
    wav = tmp_path / "speech.wav"
    write_wav(wav, audio)
    out = tmp_path / "ds"
    assert main(["generate", "--speech", str(wav), "--text", text, "--frames", "3", "--size", "160x120",
                 "--calib-frames", "0", "--no-progress", "--out", str(out)]) == 0
    info = json.loads((out / "speech" / "phones.json").read_text())
    assert info["source"] == "alignment"
    assert [p for p in info["phones"] if p != "SIL"][:4] == ["AH", "B", "L", "UW"]
    stored = read_wav(out / "speech" / "audio.wav")
    assert abs(stored.duration - audio.duration) < 1e-3
    ds = Dataset(out)
    assert ds.manifest["settings"]["speech"] == str(wav) and ds.manifest["settings"]["speech_text"] == text
    phones = PhoneTrack(tuple(info["phones"]), info["start_s"], info["end_s"])
    A = activations(phones, fps=30.0, n_frames=3)
    assert np.allclose(np.stack([f.truth["activations"] for f in ds]), A)
    with pytest.raises(ValueError, match="one source of motion"):
        from lipgen.dataset.layout import GenerateSettings

        GenerateSettings(script="AA", speech_text="hello")


def test_lipsync_with_a_trained_model(tmp_path, capsys):
    """--model: the subject's motion is projected on that model's modes (here of lip_mesh(1));
    a model of another mesh is refused before anything is written."""
    from lipgen.mesh.procedural import lip_mesh
    from lipgen.modes.model import ModeModel
    from lipgen.speech.lipsync import performer
    from lipgen.subject.activation import random_activations

    mesh = lip_mesh(1)
    U = performer(1, 0).displacements(random_activations(60, seed=3))[:, :mesh.n_nodes]
    model = ModeModel(4).fit(U, mesh=mesh)
    model.save(tmp_path / "model.npz")
    out = tmp_path / "c.npz"
    assert main(["lipsync", "--text", "Two blue fish swam.", "--model", str(tmp_path / "model.npz"),
                 "--out", str(out)]) == 0
    with np.load(out) as z:
        coef, A = z["coefficients"], z["activations"]
    want = model.project(performer(1, 0).displacements(A)[:, :mesh.n_nodes])
    assert coef.shape == (len(A), 4) and np.allclose(coef, want)
    other = ModeModel(2).fit(np.random.default_rng(0).normal(size=(5, 7, 3)))
    other.save(tmp_path / "other.npz")
    assert main(["lipsync", "--text", "Two blue fish.", "--model", str(tmp_path / "other.npz"),
                 "--out", str(tmp_path / "d.npz")]) == 1
    assert "not lipgen's procedural lips" in capsys.readouterr().err
    assert not (tmp_path / "d.npz").exists()
