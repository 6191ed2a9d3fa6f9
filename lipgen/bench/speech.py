"""Benchmark suite ``speech``: lip sync speed against the forced alignment alone.

A clip of about 10 s (Harvard list 3 spoken by eSpeak NG, 0.2 s pauses between sentences; 5 s
with ``quick``) and its transcript. Timed in the same run, on one thread (PocketSphinx is
single-threaded; BLAS is pinned to one thread for the rest):

- the forced alignment alone (both passes, no confidence pass): the baseline, as x real time
  (goal: 20x or more);
- phone recognition, and the alignment with its confidence pass;
- :func:`lipgen.speech.lipsync` in process (warm caches) and its parts;
- the whole ``lipgen lipsync`` command in a fresh interpreter (imports, model building, USD
  writing), as a ratio to the alignment alone (goal: under 2 s).

Wall-clock times on a shared machine grow with its load, so each is paired with the CPU time
of the same call (``*_cpu_s``: this process's, or the child interpreter's), which measures what
one core does whatever else runs.

Needs eSpeak NG to make the speech; without it the suite fails with that message.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
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


def _cpu(fn) -> float:
    """CPU seconds of one call of ``fn`` in this process."""
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def _child_cpu(fn) -> float:
    """CPU seconds (user + system) of the child processes one call of ``fn`` runs."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    fn()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


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
    out["align_cpu_s"] = min(_cpu(lambda: align(audio, text, confidence=False)) for _ in range(2))
    out["align_x_realtime_cpu"] = dur / out["align_cpu_s"]
    out["align_with_confidence_s"] = time_call(lambda: align(audio, text), repeat=2)["best_s"]
    out["recognize_s"] = time_call(lambda: recognize(audio), repeat=2)["best_s"]
    out["recognize_x_realtime"] = dur / out["recognize_s"]
    default_model()
    lipsync(audio, text)
    out["lipsync_warm_s"] = time_call(lambda: lipsync(audio, text), repeat=2)["best_s"]
    out["lipsync_warm_over_align"] = out["lipsync_warm_s"] / base
    out["lipsync_warm_cpu_s"] = _cpu(lambda: lipsync(audio, text))
    with tempfile.TemporaryDirectory(prefix="lipgen-bench-speech-") as work:
        wav = Path(work) / "clip.wav"
        write_wav(wav, audio)
        env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
                   PYTHONPATH=str(Path(__file__).resolve().parents[2]))

        def command():
            target = Path(work) / "lips.usdc"
            target.unlink(missing_ok=True)
            subprocess.run([sys.executable, "-m", "lipgen", "lipsync", str(wav), "--text", text,
                            "--out", str(target)], check=True, env=env, capture_output=True)

        out["command_s"] = time_call(command, repeat=1 if quick else 2)["best_s"]
        out["command_cpu_s"] = _child_cpu(command)
        out["python_startup_s"] = time_call(lambda: subprocess.run(
            [sys.executable, "-c", "import lipgen.cli; lipgen.cli.build_parser()"], check=True, env=env),
            repeat=1 if quick else 2)["best_s"]
    out["command_over_align"] = out["command_s"] / base
    out["command_cpu_over_align_cpu"] = out["command_cpu_s"] / out["align_cpu_s"]
    out["goals"] = {"align_x_realtime >= 20 (wall)": out["align_x_realtime"] >= 20,
                    "align_x_realtime_cpu >= 20": out["align_x_realtime_cpu"] >= 20,
                    "command_s < 2 on a 10 s clip (wall)": (not quick) and out["command_s"] < 2.0,
                    "command_cpu_s < 2 on a 10 s clip": (not quick) and out["command_cpu_s"] < 2.0}
    return out
