"""Test speech with exact phone timings, synthesised by eSpeak NG.

eSpeak NG (a system program, GPL-3.0; ``apt-get install espeak-ng``) is not a dependency of
lipgen: only the accuracy experiment and its tests load its library, ``libespeak-ng.so.1``, at
run time through :mod:`ctypes`. Its synthesis callback reports a *phoneme event* at the sample
where each phoneme starts (``espeakINITIALIZE_PHONEME_EVENTS``), which gives the exact truth of
the phone timings. Its phonemes (its own ASCII notation) are mapped to the ARPAbet phones of
PocketSphinx by :data:`ESPEAK_TO_ARPABET`; a diphthong written as two ARPAbet phones (``aI@`` →
``AY ER``) is split in equal halves.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import threading
from functools import lru_cache

import numpy as np

from lipgen.speech.audio import Audio, as_audio
from lipgen.speech.phones import PhoneTrack

__all__ = ["available", "synthesize", "ESPEAK_TO_ARPABET", "HARVARD"]

ESPEAK_TO_ARPABET: dict[str, tuple[str, ...]] = {
    "a": ("AE",), "aa": ("AA",), "A:": ("AA",), "A": ("AA",), "0": ("AA",), "A@": ("AA", "R"),
    "O:": ("AO",), "O": ("AO",), "O2": ("AA",), "O@": ("AO", "R"), "o@": ("AO", "R"), "oU": ("OW",),
    "OI": ("OY",), "aI": ("AY",), "aI@": ("AY", "ER"), "aI3": ("AY", "ER"), "aU": ("AW",),
    "aU@": ("AW", "ER"), "@": ("AH",), "@2": ("AH",), "@5": ("AH",), "@L": ("AH", "L"), "3": ("ER",),
    "3:": ("ER",), "V": ("AH",), "e": ("EH",), "E": ("EH",), "e@": ("EH", "R"), "eI": ("EY",),
    "I": ("IH",), "I2": ("IH",), "i": ("IY",), "i:": ("IY",), "i@": ("IH", "R"), "i@3": ("IH", "R"),
    "U": ("UH",), "u:": ("UW",), "U@": ("UH", "R"), "u@": ("UH", "R"),
    "p": ("P",), "b": ("B",), "t": ("T",), "d": ("D",), "k": ("K",), "g": ("G",), "f": ("F",),
    "v": ("V",), "s": ("S",), "z": ("Z",), "m": ("M",), "n": ("N",), "l": ("L",), "r": ("R",),
    "w": ("W",), "h": ("HH",), "j": ("Y",), "T": ("TH",), "D": ("DH",), "S": ("SH",), "Z": ("ZH",),
    "tS": ("CH",), "dZ": ("JH",), "N": ("NG",), "?": ("T",), "x": ("HH",),
}
"""eSpeak NG en-US phoneme -> ARPAbet phones. Pauses (``_``...) are ``SIL``; a suffix ``#``,
``-`` or ``/`` (variants) is dropped before the look-up."""

HARVARD: tuple[tuple[str, ...], ...] = (
    ("The birch canoe slid on the smooth planks.", "Glue the sheet to the dark blue background.",
     "It's easy to tell the depth of a well.", "These days a chicken leg is a rare dish.",
     "Rice is often served in round bowls.", "The juice of lemons makes fine punch.",
     "The box was thrown beside the parked truck.", "The hogs were fed chopped corn and garbage.",
     "Four hours of steady work faced us.", "A large size in stockings is hard to sell."),
    ("The boy was there when the sun rose.", "A rod is used to catch pink salmon.",
     "The source of the huge river is the clear spring.", "Kick the ball straight and follow through.",
     "Help the woman get back to her feet.", "A pot of tea helps to pass the evening.",
     "Smoky fires lack flame and heat.", "The soft cushion broke the man's fall.",
     "The salt breeze came across from the sea.", "The girl at the booth sold fifty bonds."),
    ("A blue crane is a tall wading bird.", "The small pup gnawed a hole in the sock.",
     "The fish twisted and turned on the bent hook.", "Press the pants and sew a button on the vest.",
     "The swan dive was far short of perfect.", "The beauty of the view stunned the young boy.",
     "Two blue fish swam in the tank.", "Her purse was full of useless trash.",
     "The colt reared and threw the tall rider.", "It snowed, rained, and hailed the same morning."),
)
"""Harvard sentences (IEEE 1969, public domain), lists 1-3. Lists 1-2 are the accuracy test set;
list 3 is kept for developing settings (never tuned on lists 1-2)."""

_LOCK = threading.Lock()


class _Event(ctypes.Structure):
    _fields_ = [("type", ctypes.c_int), ("unique_identifier", ctypes.c_uint),
                ("text_position", ctypes.c_int), ("length", ctypes.c_int),
                ("audio_position", ctypes.c_int), ("sample", ctypes.c_int),
                ("user_data", ctypes.c_void_p), ("id", ctypes.c_char * 8)]


_CALLBACK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_short), ctypes.c_int,
                             ctypes.POINTER(_Event))
_PHONEME_EVENT, _SYNCHRONOUS, _PHONEME_EVENTS, _DONT_EXIT, _UTF8 = 7, 2, 0x1, 0x8000, 1


@lru_cache(maxsize=1)
def _library():
    name = ctypes.util.find_library("espeak-ng") or "libespeak-ng.so.1"
    try:
        lib = ctypes.CDLL(name)
    except OSError:
        return None
    rate = lib.espeak_Initialize(_SYNCHRONOUS, 0, None, _PHONEME_EVENTS | _DONT_EXIT)
    return (lib, rate) if rate > 0 else None


def available() -> bool:
    """Whether eSpeak NG's library can be loaded."""
    return _library() is not None


def _arpabet(name: str) -> tuple[str, ...]:
    if name.startswith("_") or not name:
        return ("SIL",)
    if not any(c.isalnum() or c in "@?" for c in name):
        return ()  # a modifier event (e.g. ';' palatalisation), not a phoneme of its own
    for key in (name, name.rstrip("#-/;"), name.rstrip("#-/;").rstrip("2")):
        if key in ESPEAK_TO_ARPABET:
            return ESPEAK_TO_ARPABET[key]
    raise KeyError(f"eSpeak phoneme {name!r} has no ARPAbet mapping in ESPEAK_TO_ARPABET")


def synthesize(text: str, voice: str = "en-us", speed: int = 160) -> tuple[Audio, PhoneTrack]:
    """Speak ``text`` with eSpeak NG: 16 kHz audio and the true phones (source ``"truth"``).

    ``speed`` is in words per minute; ``voice`` an eSpeak voice such as ``en-us`` or ``en-us+f3``.
    """
    found = _library()
    if found is None:
        raise RuntimeError("eSpeak NG is not installed: apt-get install espeak-ng")
    lib, rate = found
    chunks, events = [], []

    def collect(wav, n, ev):
        if wav and n > 0:
            chunks.append(np.ctypeslib.as_array(wav, (n,)).copy())
        i = 0
        while ev[i].type != 0:
            if ev[i].type == _PHONEME_EVENT:
                events.append((ev[i].sample, ev[i].id.decode("ascii", "replace")))
            i += 1
        return 0

    callback = _CALLBACK(collect)
    data = text.encode("utf-8") + b"\0"
    with _LOCK:  # the library keeps global state
        lib.espeak_SetSynthCallback(callback)
        if lib.espeak_SetVoiceByName(voice.encode()) != 0:
            raise ValueError(f"eSpeak NG has no voice {voice!r}")
        lib.espeak_SetParameter(1, int(speed), 0)  # espeakRATE, absolute
        lib.espeak_Synth(data, len(data), 0, 1, 0, _UTF8, None, None)
        lib.espeak_Synchronize()
    samples = np.concatenate(chunks).astype(np.float64) / 32768.0
    n = len(samples)
    labels, start = [], []
    for sample, name in events:
        if sample >= n or not _arpabet(name):
            continue
        labels.append(_arpabet(name))
        start.append(sample / rate)
    flat, t0, t1 = [], [], []
    ends = start[1:] + [n / rate]
    for phones, a, b in zip(labels, start, ends, strict=True):
        if b <= a:
            continue
        step = (b - a) / len(phones)
        for k, p in enumerate(phones):
            if flat and p == "SIL" and flat[-1] == "SIL":
                t1[-1] = a + (k + 1) * step
                continue
            flat.append(p), t0.append(a + k * step), t1.append(a + (k + 1) * step)
    if t0 and t0[0] > 0:
        flat.insert(0, "SIL"), t0.insert(0, 0.0), t1.insert(0, t0[1])
    audio = as_audio(samples, rate, f"espeak-ng:{voice}")
    return audio, PhoneTrack(tuple(flat), np.array(t0), np.array(t1), "truth")
