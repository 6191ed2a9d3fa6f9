"""Lip-sync accuracy against known phone timings: Harvard sentences synthesised by eSpeak NG.

For each sentence of the chosen Harvard lists (:data:`lipgen.speech.espeak.HARVARD`; lists 1-2
are the test set, list 3 was used to set the transcript-confidence threshold) and each noise
level (speech-shaped noise at the given SNRs), the experiment measures

- forced alignment: the phone-start errors against eSpeak's phoneme events (median, 90th
  percentile) and how often the transcript was accepted;
- phone recognition: the phone error rate (edit distance / true phones);
- per-frame viseme agreement at 30 fps, of the aligned and of the recognised phones;

and draws one picture per sentence list (first sentence, clean): waveform, true, aligned and
recognised phones, and the mode-coefficient curves of the aligned lip sync.
"""

from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

__all__ = ["LipsyncSettings", "run_lipsync_experiment"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class LipsyncSettings:
    """Settings of the lip-sync accuracy experiment."""

    lists: tuple[int, ...] = (1, 2)
    snr_db: tuple[float, ...] = (float("inf"), 20.0, 10.0)
    voices: tuple[str, ...] = ("en-us", "en-us+m3", "en-us+f2")
    speed_wpm: int = 160
    fps: float = 30.0
    max_sentences: int | None = None
    pictures: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.lists or any(isinstance(k, bool) or not isinstance(k, int) for k in self.lists):
            raise ValueError(f"lists must be one or more Harvard list numbers, got {self.lists!r}")
        if not self.snr_db or any(np.isnan(s) or s < -30 for s in self.snr_db):
            raise ValueError(f"snr_db must be one or more ratios in dB >= -30 (inf: clean), "
                             f"got {self.snr_db!r}")
        n = self.max_sentences
        if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
            raise ValueError(f"max_sentences must be at least 1 (or None: all), got {self.max_sentences!r}")

    def report_files(self) -> tuple[str, ...]:
        """The files :func:`run_lipsync_experiment` writes into its folder."""
        pictures = tuple(f"list{k}.png" for k in self.lists) if self.pictures else ()
        return ("report.md", "lipsync.json", *pictures)


def _pct(x, q) -> float:
    return float(np.percentile(x, q)) if len(x) else float("nan")


def _one(text: str, audio, truth, fps: float) -> dict:
    from lipgen.speech.decode import MIN_CONFIDENCE, AlignmentError, align, recognize
    from lipgen.speech.score import boundary_errors, phone_error_rate, viseme_agreement

    t0 = time.perf_counter()
    try:
        aligned = align(audio, text)
    except AlignmentError:
        aligned = None
    t1 = time.perf_counter()
    rec = recognize(audio)
    t2 = time.perf_counter()
    row = {"text": text, "duration_s": audio.duration, "align_s": t1 - t0, "recognize_s": t2 - t1,
           "per": phone_error_rate(truth, rec),
           "viseme_agreement_recognized": viseme_agreement(truth, rec, fps)}
    if aligned is not None:
        err, same = boundary_errors(truth, aligned)
        row.update(boundary_errors_s=err.tolist(), same_phone_share=same, confidence=aligned.confidence,
                   accepted=aligned.confidence >= MIN_CONFIDENCE,
                   viseme_agreement_aligned=viseme_agreement(truth, aligned, fps))
    else:
        row.update(boundary_errors_s=[], same_phone_share=0.0, confidence=0.0, accepted=False,
                   viseme_agreement_aligned=float("nan"))
    return row, aligned, rec


def _summary(rows: list[dict]) -> dict:
    err = np.concatenate([r["boundary_errors_s"] for r in rows]) if rows else np.zeros(0)
    speech = sum(r["duration_s"] for r in rows)
    return {"sentences": len(rows), "phone_boundaries": int(len(err)),
            "boundary_error_median_ms": 1000 * _pct(err, 50), "boundary_error_p90_ms": 1000 * _pct(err, 90),
            "within_30ms": float(np.mean(err <= 0.03)) if len(err) else float("nan"),
            "transcripts_accepted": float(np.mean([r["accepted"] for r in rows])),
            "same_phone_share": float(np.mean([r["same_phone_share"] for r in rows])),
            "phone_error_rate": float(np.mean([r["per"] for r in rows])),
            "viseme_agreement_aligned": float(np.nanmean([r["viseme_agreement_aligned"] for r in rows])),
            "viseme_agreement_recognized": float(np.mean([r["viseme_agreement_recognized"] for r in rows])),
            "align_with_confidence_x_realtime": speech / max(sum(r["align_s"] for r in rows), 1e-9)}


def _picture(path: Path, text, audio, truth, aligned, rec, fps) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lipgen.speech.lipsync import default_model, project_activations
    from lipgen.speech.visemes import activations

    fig, ax = plt.subplots(3, 1, figsize=(11, 7), sharex=True, gridspec_kw={"height_ratios": [1.2, 1.3, 2]})
    t = np.arange(len(audio.samples)) / audio.rate
    ax[0].plot(t, audio.samples, lw=0.4, color="0.3")
    ax[0].set_ylabel("waveform")
    ax[0].set_title(text, fontsize=10)
    for row, track in enumerate((truth, aligned, rec)):
        if track is None:
            continue
        for lab, a, b in zip(track.labels, track.start, track.end, strict=True):
            if lab == "SIL":
                continue
            ax[1].add_patch(plt.Rectangle((a, 2 - row - 0.4), b - a, 0.8, fc=f"C{row}", alpha=0.35,
                                          ec="k", lw=0.3))
            ax[1].text((a + b) / 2, 2 - row, lab, ha="center", va="center", fontsize=6)
    ax[1].set_yticks([2, 1, 0], ["truth", "aligned", "recognised"])
    ax[1].set_ylim(-0.6, 2.6)
    if aligned is not None:
        n = int(np.ceil(audio.duration * fps)) + 1
        model = default_model()
        coef = project_activations(activations(aligned, fps, n), model, 0)
        ax[2].plot(np.arange(n) / fps, coef, lw=1)
    ax[2].set_ylabel("mode coefficients")
    ax[2].set_xlabel("time (s)")
    ax[2].set_xlim(0, audio.duration)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_lipsync_experiment(out: str | os.PathLike, settings: LipsyncSettings = LipsyncSettings()) -> Path:
    """Run the experiment, write ``report.md``, ``lipsync.json`` and pictures to ``out``."""
    from tqdm import tqdm

    from lipgen.speech import espeak
    from lipgen.speech.score import speech_shaped_noise

    if not espeak.available():
        raise RuntimeError("the lip-sync experiment needs eSpeak NG: apt-get install espeak-ng")
    for k in settings.lists:
        if not 1 <= k <= len(espeak.HARVARD):
            raise ValueError(f"Harvard list {k} is not stored; choose from 1..{len(espeak.HARVARD)}")
    out = Path(out)
    out.mkdir(exist_ok=True)  # its parent exists (the command checks it): no folders made on the way
    jobs = [(k, i, s) for k in settings.lists for i, s in enumerate(espeak.HARVARD[k - 1])]
    jobs = jobs[:settings.max_sentences] if settings.max_sentences else jobs
    results = {str(snr): [] for snr in settings.snr_db}
    pictures = []
    for n, (k, i, text) in enumerate(tqdm(jobs, desc="lipsync sentences", disable=None)):
        voice = settings.voices[n % len(settings.voices)]
        clean, truth = espeak.synthesize(text, voice, settings.speed_wpm)
        for snr in settings.snr_db:
            audio = clean if not np.isfinite(snr) else speech_shaped_noise(clean, snr, settings.seed + n)
            row, aligned, rec = _one(text, audio, truth, settings.fps)
            row.update(list=k, voice=voice, snr_db=snr)
            results[str(snr)].append(row)
            if settings.pictures and i == 0 and not np.isfinite(snr):
                pic = out / f"list{k}.png"
                _picture(pic, text, audio, truth, aligned, rec, settings.fps)
                pictures.append(pic.name)
    summary = {snr: _summary(rows) for snr, rows in results.items()}
    data = {"settings": asdict(settings), "summary": summary, "sentences": results}
    (out / "lipsync.json").write_text(json.dumps(data, indent=1, default=float))
    lines = ["# Lip sync accuracy (eSpeak NG speech, exact phone timings)", "",
             f"Harvard lists {', '.join(map(str, settings.lists))}, voices {', '.join(settings.voices)} "
             f"at {settings.speed_wpm} wpm; speech-shaped noise. Phone-start errors over the phones paired "
             "by edit distance (pauses left out); PER = edit distance / true phones. Speeds here include "
             "the confidence pass and whatever else the machine runs (see `lipgen bench --suite speech`).",
             "",
             "| SNR dB | sentences | boundary median ms | p90 ms | <= 30 ms | transcripts accepted | "
             "PER (recognition) | viseme agreement aligned | recognised | align + confidence x real time |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for snr, s in summary.items():
        lines.append(f"| {snr} | {s['sentences']} | {s['boundary_error_median_ms']:.1f} | "
                     f"{s['boundary_error_p90_ms']:.1f} | {100 * s['within_30ms']:.0f}% | "
                     f"{100 * s['transcripts_accepted']:.0f}% | {100 * s['phone_error_rate']:.0f}% | "
                     f"{100 * s['viseme_agreement_aligned']:.0f}% | "
                     f"{100 * s['viseme_agreement_recognized']:.0f}% | "
                     f"{s['align_with_confidence_x_realtime']:.1f} |")
    lines += [""] + [f"![{p}]({p})" for p in pictures]
    report = out / "report.md"
    report.write_text("\n".join(lines) + "\n")
    return report
