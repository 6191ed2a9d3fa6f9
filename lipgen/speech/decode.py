"""Phones with timings from audio, by PocketSphinx: forced alignment with a transcript, or phone
recognition without one.

Both use the en-US acoustic model shipped in the ``pocketsphinx`` wheel (continuous HMMs, 10 ms
frames): alignment searches the transcript's pronunciations (with optional pauses between words)
and then aligns the best path phone by phone (``Decoder.set_align_text`` / ``set_alignment``);
recognition searches a phone loop weighted by the shipped phone language model
(``en-us-phone.lm.bin``, "allphone" search).

**Confidence of a transcript.** A transcript that does not match the audio still aligns (it is
forced), but its acoustic score per frame falls well below that of the free phone loop on the
same audio, which may choose any phones. ``confidence = exp(gap / scale)`` with ``gap`` the
per-frame log-likelihood of the alignment minus that of the phone loop (clipped at 0) and
:data:`CONFIDENCE_SCALE`; :func:`phones_from_audio` falls back to recognition, with a warning,
below :data:`MIN_CONFIDENCE`.
"""

from __future__ import annotations

import logging
import math
import threading

import numpy as np

from lipgen.speech.audio import Audio, NoSpeechError, check_speech
from lipgen.speech.phones import PHONES, PhoneTrack, check_words, pronunciations, words_of

__all__ = ["align", "recognize", "phones_from_audio", "CONFIDENCE_SCALE", "MIN_CONFIDENCE",
           "AlignmentError"]

log = logging.getLogger(__name__)

FRAME = 0.01  # s, PocketSphinx's frame period
PAD = 0.25  # s of silence added at both ends before decoding (removed from the times)
CONFIDENCE_SCALE = 1e-3
"""Score per frame by which an alignment may fall below the phone loop for confidence 1/e.

PocketSphinx's acoustic scores are log-likelihoods normalised by the best score of each frame
and scaled down, hence the small numbers."""
MIN_CONFIDENCE = 0.15
"""Below this transcript confidence the phones come from recognition instead (with a warning).

Set on Harvard list 3 (espeak-ng, clean and at 10 dB SNR of white noise; lists 1-2 are the test
set) as the midpoint, 0.0019 per frame below the phone loop, between the true transcripts
(0.0005-0.0012) and those of another sentence (0.0025 and more). Re-measured with the final
decoders (a fresh one per utterance; the reused ones give the same): true transcripts
0.0004-0.0013 (all pass), one word swapped 0.0005-0.0017 (all pass), half
the words wrong 0.0016-0.0024 or not alignable (two of
six that aligned pass), the words reversed 0.0021-0.0036 or not alignable (all refused),
another sentence never alignable. (A first threshold of 0.25 was dropped after a true list-1
transcript scored 0.23 under it.)

One wrong word is not caught, by this score or by local ones. On list 3 (10 sentences, voices
en-us and en-us+f2, clean and 10 dB speech-shaped noise; one word swapped for another
dictionary word; 40 true and 34 alignable swapped), the worst word's gap to the phone loop over
its own frames ranged -0.0055..-0.0012 per frame for true transcripts and -0.0100..-0.0024 with
the swapped word; summed over the word's frames, -0.170..-0.028 against -0.268..-0.064; a per-
word segment-wise phone loop and the alignment score alone overlap too. Any threshold either
refuses true transcripts (which then lose their alignment for a far worse recognition) or
passes some swapped words, so a one-word error is left to the alignment, which keeps the other
words' timings."""
_LOG_BASE = math.log(1.0001)  # PocketSphinx scores are in units of log base 1.0001


class AlignmentError(RuntimeError):
    """PocketSphinx found no path through the transcript (it does not fit the audio at all)."""


_LOCAL = threading.local()  # each thread its own decoders (a decoder is not thread-safe)


def _decoder(kind: str, lexicon: dict[str, tuple[str, ...]] | None = None):
    """The PocketSphinx decoder ``kind`` of this thread: ``"align"`` (knowing ``lexicon``'s words,
    added to those it knew) or ``"phones"``; built on first use, then reused.

    A reused decoder carries state from the utterances it decoded: its front end's *live*
    cepstral mean normalisation keeps the running mean (and the sums it is updated from) of
    everything it heard, so the features, and the results, for the same audio changed with
    what came before (restoring the mean with ``set_cmn`` is not enough, the sums stay).
    ``reinit_feat`` before each utterance rebuilds the front end as a new decoder has it:
    the results are then those of a fresh decoder, whatever ran before (tested). Without the
    134k-word dictionary (words are added one by one) a decoder is built in about 0.01 s.
    """
    cache = getattr(_LOCAL, "decoders", None)
    if cache is None:
        cache = _LOCAL.decoders = {}
    if kind in cache:
        dec, known = cache[kind]
        dec.reinit_feat()
    else:
        dec, known = _new_decoder(kind), set()
        cache[kind] = dec, known
    for word, phones in (lexicon or {}).items():
        if word not in known:
            dec.add_word(word, " ".join(phones), False)
            known.add(word)
    return dec


def _new_decoder(kind: str):
    import os

    from lipgen._optional import require

    ps = require("pocketsphinx", "lip sync from speech")
    if kind == "align":
        return ps.Decoder(samprate=16000, lm=None, dict=os.devnull, bestpath=False, beam=1e-48,
                          pbeam=1e-48, wbeam=1e-48, loglevel="FATAL")
    if kind != "phones":
        raise ValueError(f"decoder kind must be 'align' or 'phones', got {kind!r}")
    lm = f"{ps.get_model_path()}/en-us/en-us-phone.lm.bin"
    return ps.Decoder(samprate=16000, lm=None, dict=os.devnull, allphone=lm, backtrace=True, beam=1e-20,
                      pbeam=1e-20, lw=2.0, loglevel="FATAL")


def _pcm(audio: Audio) -> bytes:
    """16-bit PCM padded with :data:`PAD` s of silence at both ends (a clip cut right at the
    speech leaves the search no silence to start and end in), with a seeded dither of 1 LSB
    (digital silence, log 0 energy, derails the features of PocketSphinx's front end)."""
    pad = np.zeros(int(round(PAD * audio.rate)))
    x = np.concatenate([pad, audio.samples, pad])
    x = x + np.random.default_rng(len(x)).normal(0.0, 1.0 / 32768.0, len(x))
    return (np.clip(x, -1.0, 1.0) * 32767.0).round().astype("<i2").tobytes()


def _decode(dec, pcm: bytes) -> None:
    dec.start_utt()
    dec.process_raw(pcm, full_utt=True)
    dec.end_utt()


def _track(items: list[tuple[str, int, int]], n_frames: int, source: str, confidence=1.0) -> PhoneTrack:
    """A contiguous PhoneTrack from (label, first frame, last frame) items of the padded audio;
    gaps become SIL."""
    shift = int(round(PAD / FRAME))
    items = [(label, a - shift, min(b - shift, n_frames - 1)) for label, a, b in items]
    labels, start, end = [], [], []
    t = 0
    for label, a, b in items:
        label = label if label in PHONES else "SIL"
        if a > t:
            labels.append("SIL"), start.append(t), end.append(a)
        a = max(a, t)
        if b + 1 <= a:
            continue
        if labels and labels[-1] == "SIL" and label == "SIL":
            end[-1] = b + 1
        else:
            labels.append(label), start.append(a), end.append(b + 1)
        t = b + 1
    if t < n_frames:
        labels.append("SIL"), start.append(t), end.append(n_frames)
    return PhoneTrack(tuple(labels), np.array(start) * FRAME, np.array(end) * FRAME, source, confidence)


def _n_frames(audio: Audio) -> int:
    return max(1, int(round(audio.duration / FRAME)))


def recognize(audio: Audio) -> PhoneTrack:
    """Phones with timings by phone recognition (no transcript).

    Raises :class:`~lipgen.speech.audio.NoSpeechError` for silence.
    """
    check_speech(audio)
    track, _ = _recognize(audio)
    if all(label == "SIL" for label in track.labels):
        raise NoSpeechError(f"no speech found in {audio.source}: the recogniser heard only silence")
    return track


def _recognize(audio: Audio) -> tuple[PhoneTrack, float]:
    """(phones, total scaled acoustic log-likelihood)."""
    dec = _decoder("phones")
    _decode(dec, _pcm(audio))
    segs = [(s.word, s.start_frame, s.end_frame, s.ascore) for s in dec.seg()]
    score = sum(math.log(max(s[3], 1e-300)) for s in segs)  # seg() gives exp(score)
    return _track([s[:3] for s in segs], _n_frames(audio), "recognition"), score


def align(audio: Audio, text: str, confidence: bool = True) -> PhoneTrack:
    """Phones with timings by forced alignment of ``text`` to ``audio``.

    The track's ``confidence`` says how well the transcript fits (module doc; it costs a phone
    recognition pass: with ``confidence=False`` it is skipped and reported as NaN). Raises
    :class:`~lipgen.speech.phones.TextError` for words missing from the dictionary or
    non-English text, :class:`AlignmentError` when no alignment exists at all.
    """
    check_speech(audio)
    words = [w for clause in words_of(text) for w in clause]
    lexicon = pronunciations()
    check_words(words, lexicon)
    dec = _decoder("align", {w: lexicon[w] for w in words})
    pcm = _pcm(audio)
    dec.set_align_text(" ".join(words))
    try:
        _decode(dec, pcm)
        if dec.hyp() is None:
            raise AlignmentError(f"the transcript could not be aligned to {audio.source} at all")
        dec.set_alignment()  # second pass: phone by phone within the words found
        _decode(dec, pcm)
    except RuntimeError as exc:  # PocketSphinx reports a failed search as RuntimeError
        if isinstance(exc, AlignmentError):
            raise
        raise AlignmentError(f"the transcript could not be aligned to {audio.source} ({exc})") from exc
    items, score = [], 0.0
    for word in dec.get_alignment():
        for phone in word:
            items.append((phone.name, phone.start, phone.start + phone.duration - 1))
            score += phone.score
    n = _n_frames(audio)
    if not confidence:
        return _track(items, n, "alignment", float("nan"))
    _, loop = _recognize(audio)
    gap = min(0.0, (score * _LOG_BASE - loop) / (len(pcm) // 320))
    fit = math.exp(gap / CONFIDENCE_SCALE)
    log.info("aligned %d words to %s: confidence %.2f (%.5f per frame below the phone loop)",
             len(words), audio.source, fit, -gap)
    return _track(items, n, "alignment", fit)


def phones_from_audio(audio: Audio, text: str | None = None,
                      min_confidence: float = MIN_CONFIDENCE) -> PhoneTrack:
    """Phones of ``audio``: aligned to ``text`` when given and it fits, else recognised.

    A transcript whose confidence is below ``min_confidence`` (or that does not align at all) is
    reported with a warning, and the phones come from recognition instead.
    """
    if text is None:
        return recognize(audio)
    try:
        track = align(audio, text)
    except AlignmentError as exc:
        log.warning("%s; using phone recognition instead", exc)
        return recognize(audio)
    if track.confidence < min_confidence:
        log.warning("the transcript does not match the audio (alignment confidence %.2f < %.2f); "
                    "using phone recognition instead", track.confidence, min_confidence)
        return recognize(audio)
    return track
