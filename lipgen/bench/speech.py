"""Benchmark suite ``speech``: lip sync speed against the forced alignment alone.

A clip of about 10 s (Harvard list 3 spoken by eSpeak NG, 0.2 s pauses between sentences; 5 s
with ``quick``) and its transcript. Timed in the same run, on one thread (PocketSphinx is
single-threaded; BLAS is pinned to one thread for the rest):

- the forced alignment alone (both passes, no confidence pass): the baseline, as x real time
  (goal: 20x or more);
- phone recognition, and the alignment with its confidence pass;
- :func:`lipgen.speech.lipsync` in process (warm caches) and, in CPU seconds, each part of the
  command (``parts_cpu_s``: dictionary, alignment, confidence pass, default lips, projection,
  USD writing, the imports of a fresh interpreter);
- the whole ``lipgen lipsync`` command in a fresh interpreter (imports, default lips, USD
  writing), as a ratio to the alignment alone (goal: under 2 s);
- a profile of the whole command by py-spy when it is installed and allowed to trace
  (``command_profile``: the functions with the largest share of samples, inclusive).

Wall-clock times on a shared machine grow with its load, so each is paired with the CPU time
of the same call (``*_cpu_s``: this process's, or the child interpreter's), which measures what
one core does whatever else runs; the load average is recorded before and after.

Needs eSpeak NG to make the speech; without it the suite fails with that message.
"""

from __future__ import annotations

import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from lipgen.bench.measure import time_call

NAME = "speech"


def _clip(seconds: float):
    from lipgen.speech import espeak
    from lipgen.speech.audio import Audio

    if not espeak.available():
        raise RuntimeError("the speech benchmark needs eSpeak NG to make speech: apt-get install espeak-ng")
    parts, texts = [], []
    for text in espeak.HARVARD[2]:
        audio, _ = espeak.synthesize(text)
        parts += [audio.samples, np.zeros(3200)]
        texts.append(text)
        if sum(map(len, parts)) >= seconds * 16000:
            break
    return Audio(np.concatenate(parts), source="bench clip"), " ".join(texts)


def _threadpool_one():
    try:
        from threadpoolctl import threadpool_limits

        return threadpool_limits(1)
    except ImportError:  # pragma: no cover - threadpoolctl comes with scipy's stack
        return None


def _cpu(fn, repeat: int = 1) -> float:
    """Least CPU seconds of ``repeat`` calls of ``fn`` in this process."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def _child_cpu(fn) -> float:
    """CPU seconds (user + system) of the child processes one call of ``fn`` runs."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    fn()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _parts(audio, text, work: Path, repeat: int) -> dict:
    """CPU seconds of each part of the command, in this process (warm)."""
    from lipgen.speech import decode
    from lipgen.speech.lipsync import LipSync, default_model, model_mesh, project_activations
    from lipgen.speech.outputs import write_lipsync
    from lipgen.speech.phones import _load_dictionary, dictionary_path, pronunciations, words_of
    from lipgen.speech.visemes import activations

    words = [w for clause in words_of(text) for w in clause]
    track = decode.align(audio, text, confidence=False)
    model = default_model()
    A = activations(track, 30.0, int(np.ceil(audio.duration * 30.0)) + 1)
    coef = project_activations(A, model, 0)
    result = LipSync(track, 30.0, A, coef, model, audio, text)
    wav = work / "parts.wav"

    def dictionary():
        _load_dictionary.cache_clear()
        lex = pronunciations(dictionary_path())
        return [lex[w] for w in words]

    def usd():
        target = work / "parts.usdc"
        target.unlink(missing_ok=True)
        write_lipsync(target, result, mesh=model_mesh(0), wav=wav)

    from lipgen.speech.audio import write_wav

    write_wav(wav, audio)
    usd()  # warm: pxr imported (the imports are timed with the interpreter's)
    out = {"dictionary": _cpu(dictionary, repeat),
           "alignment": _cpu(lambda: decode.align(audio, text, confidence=False), repeat),
           "confidence_pass": _cpu(lambda: decode._recognize(audio), repeat),
           "viseme_dynamics": _cpu(lambda: activations(track, 30.0, len(A)), repeat),
           "projection": _cpu(lambda: project_activations(A, model, 0), repeat),
           "usd_write": _cpu(usd, repeat)}
    return out


def _profile(cmd: list[str], env: dict, work: Path, top: int = 15) -> dict:
    """Inclusive shares of the functions py-spy sampled most in a run of ``cmd``."""
    spy = shutil.which("py-spy") or str(Path(sys.executable).with_name("py-spy"))
    if not Path(spy).is_file():
        return {"error": "py-spy is not installed (pip install py-spy)"}
    raw = work / "profile.txt"
    run = subprocess.run([spy, "record", "-r", "250", "-f", "raw", "-o", str(raw), "--", *cmd], env=env,
                         capture_output=True, text=True)
    if run.returncode != 0 or not raw.is_file():
        return {"error": f"py-spy failed: {(run.stderr or run.stdout).strip()[-300:]}"}
    total, inclusive = 0, Counter()
    for line in raw.read_text().splitlines():
        stack, _, n = line.rpartition(" ")
        if not n.isdigit():
            continue
        total += int(n)
        for frame in {re.sub(r":\d+\)$", ")", f) for f in stack.split(";")}:  # per function
            inclusive[frame] += int(n)
    lipgen_frames = [(f, c) for f, c in inclusive.most_common() if "lipgen/" in f or "pxr/" in f]
    return {"samples": total, "rate_hz": 250,
            "top": [[f, round(c / max(total, 1), 3)] for f, c in lipgen_frames[:top]]}


def run(quick: bool = False) -> dict:
    from lipgen.speech.audio import write_wav
    from lipgen.speech.decode import align, recognize
    from lipgen.speech.lipsync import default_model, lipsync

    _threadpool_one()
    audio, text = _clip(5.0 if quick else 10.0)
    dur = audio.duration
    align(audio, text, confidence=False)  # warm: decoders built, dictionary read
    out: dict = {"clip_s": dur, "load_avg_1min": os.getloadavg()[0]}
    base = time_call(lambda: align(audio, text, confidence=False), repeat=3)["best_s"]
    out["align_s"] = base
    out["align_x_realtime"] = dur / base
    out["align_cpu_s"] = _cpu(lambda: align(audio, text, confidence=False), repeat=2 if quick else 3)
    out["align_x_realtime_cpu"] = dur / out["align_cpu_s"]
    out["align_with_confidence_s"] = time_call(lambda: align(audio, text), repeat=2)["best_s"]
    out["recognize_s"] = time_call(lambda: recognize(audio), repeat=2)["best_s"]
    out["recognize_x_realtime"] = dur / out["recognize_s"]
    default_model()
    lipsync(audio, text)
    out["lipsync_warm_s"] = time_call(lambda: lipsync(audio, text), repeat=2)["best_s"]
    out["lipsync_warm_over_align"] = out["lipsync_warm_s"] / base
    out["lipsync_warm_cpu_s"] = _cpu(lambda: lipsync(audio, text))
    with tempfile.TemporaryDirectory(prefix="lipgen-bench-speech-") as tmp:
        work = Path(tmp)
        out["parts_cpu_s"] = _parts(audio, text, work, repeat=1 if quick else 2)
        wav = work / "clip.wav"
        write_wav(wav, audio)
        env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
                   PYTHONPATH=str(Path(__file__).resolve().parents[2]))
        target = work / "lips.usdc"
        cmd = [sys.executable, "-m", "lipgen", "lipsync", str(wav), "--text", text, "--out", str(target),
               "--force"]

        def command():
            subprocess.run(cmd, check=True, env=env, capture_output=True)

        def imports():
            subprocess.run([sys.executable, "-c", "import lipgen.cli, lipgen.commands.lipsync, "
                            "lipgen.speech.lipsync, lipgen.speech.outputs, pocketsphinx, pxr.Usd, "
                            "pxr.UsdGeom, pxr.UsdSkel, pxr.UsdMedia"], check=True, env=env)

        command()  # warm the file cache
        out["command_s"] = time_call(command, repeat=1 if quick else 3)["best_s"]
        out["command_cpu_s"] = min(_child_cpu(command) for _ in range(1 if quick else 3))
        out["parts_cpu_s"]["interpreter_and_imports"] = min(_child_cpu(imports) for _ in range(2))
        out["python_startup_s"] = time_call(lambda: subprocess.run(
            [sys.executable, "-c", "import lipgen.cli; lipgen.cli.build_parser()"], check=True, env=env),
            repeat=1 if quick else 2)["best_s"]
        if not quick:
            out["command_profile"] = _profile(cmd, env, work)
    out["load_avg_1min_after"] = os.getloadavg()[0]
    out["command_over_align"] = out["command_s"] / base
    out["command_cpu_over_align_cpu"] = out["command_cpu_s"] / out["align_cpu_s"]
    out["goals"] = {"align_x_realtime >= 20 (wall)": out["align_x_realtime"] >= 20,
                    "align_x_realtime_cpu >= 20": out["align_x_realtime_cpu"] >= 20,
                    "command_s < 2 on a 10 s clip (wall)": (not quick) and out["command_s"] < 2.0,
                    "command_cpu_s < 2 on a 10 s clip": (not quick) and out["command_cpu_s"] < 2.0}
    return out
