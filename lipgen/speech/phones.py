"""Phones with timings, English text to words and pronunciations, and a duration model.

Phones are the 39 ARPAbet phones of the CMU dictionary (as PocketSphinx's en-US model uses
them, without stress marks) plus ``SIL``. Pronunciations come from the dictionary shipped in
the ``pocketsphinx`` wheel (``cmudict-en-us.dict``, the first variant of each word).

Durations for text without audio follow Klatt's rules (D. H. Klatt, "Synthesis by rule of
segmental durations in English sentences", 1979; as in J. Allen, M. S. Hunnicutt and D. H.
Klatt, *From Text to Speech: The MITalk System*, 1987, ch. 9): each phone has an inherent
duration ``INH`` and a minimum ``MIN`` (ms), and ``DUR = MIN + (INH - MIN) * PRCNT``, where
``PRCNT`` multiplies the factors of the rules below. The INH/MIN values are the Klatt table as
distributed with the Festival speech synthesis system (``klatt_durs.scm``, mrpa phone set),
mapped to ARPAbet; ``AH`` takes the schwa's values since the dictionary marks no stress and
most ``AH`` in running speech are reduced. Rules applied (numbering as Klatt 1979):

- 2, clause-final lengthening: vowels of a clause's last syllable x1.4;
- 4, non-word-final shortening: vowels not in a word's last syllable x0.85;
- 5, polysyllabic shortening: vowels of words of several syllables x0.8;
- 6, non-initial consonant shortening: consonants not word-initial x0.85;
- 7, unstressed shortening: the phones of function words (no lexical stress) x0.5 (vowels)
  and x0.7 (consonants);
- 10, cluster shortening: a vowel after a vowel x0.7, a consonant between consonants x0.5,
  next to one consonant x0.7;

and a pause of 200 ms at a clause boundary (comma, semicolon, colon) and of 300 ms at the ends.
Stress rules (and emphasis) need stress marks, which this dictionary lacks: they are left out.
"""

from __future__ import annotations

import os
import re
import unicodedata
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from lipgen.errors import LipgenError

__all__ = ["PHONES", "VOWELS", "PhoneTrack", "TextError", "dictionary_path", "pronunciations",
           "words_of", "text_phones", "KLATT_MS"]

VOWELS = ("AA", "AE", "AH", "AO", "AW", "AY", "EH", "ER", "EY", "IH", "IY", "OW", "OY", "UH", "UW")
"""The 15 vowel phones (diphthongs included) of the CMU dictionary's ARPAbet."""
CONSONANTS = ("B", "CH", "D", "DH", "F", "G", "HH", "JH", "K", "L", "M", "N", "NG", "P", "R", "S",
              "SH", "T", "TH", "V", "W", "Y", "Z", "ZH")
PHONES = VOWELS + CONSONANTS + ("SIL",)
"""The phone labels a :class:`PhoneTrack` may hold."""

KLATT_MS: dict[str, tuple[float, float]] = {
    "AA": (240, 100), "AE": (230, 80), "AH": (120, 60), "AO": (240, 130), "AW": (240, 100),
    "AY": (250, 150), "EH": (150, 70), "ER": (180, 80), "EY": (180, 100), "IH": (135, 40),
    "IY": (155, 55), "OW": (220, 80), "OY": (280, 150), "UH": (210, 70), "UW": (230, 150),
    "B": (85, 60), "CH": (70, 50), "D": (75, 50), "DH": (50, 30), "F": (100, 80), "G": (80, 60),
    "HH": (80, 20), "JH": (70, 50), "K": (80, 60), "L": (80, 40), "M": (70, 60), "N": (60, 50),
    "NG": (95, 60), "P": (90, 50), "R": (80, 30), "S": (105, 60), "SH": (105, 80), "T": (75, 50),
    "TH": (90, 60), "V": (60, 40), "W": (80, 60), "Y": (80, 40), "Z": (75, 40), "ZH": (70, 40),
}
"""Klatt's inherent and minimum durations (ms) per phone (see the module doc for the source)."""

_FUNCTION_WORDS = frozenset(
    "a an the of to in on at by for with from and or but as is are was were be been am it its "
    "he she we they you i me him her us them his their our your my that this than then so if "
    "not no do does did has have had will would can could shall should may might must".split())
_CLAUSE_PAUSE, _EDGE_PAUSE = 0.2, 0.3


class TextError(LipgenError, ValueError):
    """A transcript lipgen cannot turn into phones (not English, words missing from the dictionary)."""


@dataclass(frozen=True, eq=False)
class PhoneTrack:
    """Phones with timings.

    Attributes
    ----------
    labels : tuple of str
        Phone labels from :data:`PHONES`.
    start, end : (p,) float
        Start and end of each phone (s); contiguous: ``start[i+1] == end[i]``.
    source : str
        How they were found: ``"alignment"``, ``"recognition"``, ``"text"`` or ``"truth"``.
    confidence : float
        For an alignment: the transcript's fit to the audio in [0, 1] (see
        :func:`lipgen.speech.decode.align`; NaN if not measured); 1.0 otherwise.
    """

    labels: tuple
    start: np.ndarray
    end: np.ndarray
    source: str = "text"
    confidence: float = 1.0

    def __post_init__(self) -> None:
        start = np.asarray(self.start, float)
        end = np.asarray(self.end, float)
        if start.shape != (len(self.labels),) or end.shape != start.shape:
            raise ValueError(f"a PhoneTrack needs start and end of shape ({len(self.labels)},), got "
                             f"{start.shape} and {end.shape}")
        if len(start) and (not np.isfinite(start).all() or (end <= start).any()):
            raise ValueError("phone times must be finite with end > start for every phone")
        unknown = sorted(set(self.labels) - set(PHONES))
        if unknown:
            raise ValueError(f"unknown phone labels {unknown}; the phone set is {', '.join(PHONES)}")
        object.__setattr__(self, "labels", tuple(self.labels))
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "end", end)

    def __len__(self) -> int:
        return len(self.labels)

    @property
    def duration(self) -> float:
        return float(self.end[-1]) if len(self) else 0.0

    def at(self, times) -> np.ndarray:
        """(t,) index of the phone sounding at each time (s); the last phone after the end."""
        i = np.searchsorted(self.end, np.asarray(times, float), side="right")
        return np.minimum(i, len(self) - 1)


def dictionary_path() -> Path:
    """The CMU pronouncing dictionary shipped in the ``pocketsphinx`` wheel."""
    from lipgen._optional import require

    ps = require("pocketsphinx", "lip sync from speech")
    return Path(ps.get_model_path()) / "en-us" / "cmudict-en-us.dict"


class _Lexicon(Mapping):
    """Word -> phones over the dictionary's text, looked up word by word: a substring search for
    the line ``"\nword "`` (keys are unique, one a line) from the first line that starts with the
    word's letter (the dictionary lists words by letter, so that skips most of it). Parsing all
    134k pronunciations up front costs a tenth of a second; a look-up, tens of microseconds."""

    def __init__(self, text: str) -> None:
        self._text = "\n" + text if not text.startswith("\n") else text
        self._all: dict[str, str] | None = None
        self._starts: dict[str, int] = {}

    def _start(self, letter: str) -> int:
        if letter not in self._starts:
            self._starts[letter] = self._text.find("\n" + letter)
        return self._starts[letter]

    def _line(self, word: object) -> str | None:
        if not isinstance(word, str) or not word or any(c in word for c in " \n"):
            return None
        start = self._start(word[0])  # no line of the word can come before it
        i = -1 if start < 0 else self._text.find(f"\n{word} ", start)
        if i < 0:
            return None
        start = i + len(word) + 2
        end = self._text.find("\n", start)
        return self._text[start:end if end >= 0 else len(self._text)]

    def __getitem__(self, word: str) -> tuple[str, ...]:
        line = self._line(word)
        if line is None:
            raise KeyError(word)
        return tuple(line.split())

    def __contains__(self, word: object) -> bool:
        return self._line(word) is not None

    def _index(self) -> dict[str, str]:
        if self._all is None:
            self._all = dict(line.split(" ", 1) for line in self._text.splitlines() if " " in line)
        return self._all

    def __iter__(self):
        return iter(self._index())

    def __len__(self) -> int:
        return len(self._index())


@lru_cache(maxsize=2)
def _load_dictionary(path: str) -> _Lexicon:
    # variants are keyed "word(2)": words_of never yields parentheses, so the first variant wins
    with open(path, encoding="utf-8") as fh:
        return _Lexicon(fh.read())


def pronunciations(path: str | os.PathLike | None = None) -> Mapping[str, tuple[str, ...]]:
    """Word -> phones, read once from the dictionary (by default :func:`dictionary_path`)."""
    return _load_dictionary(str(path or dictionary_path()))


_WORD = re.compile(r"[a-z]+(?:['.-][a-z]+)*'?")


def words_of(text: str) -> list[list[str]]:
    """Clauses of lower-case words of an English ``text`` (split at , ; : . ! ?).

    Raises :class:`TextError` for text in a non-Latin script, and ``ValueError`` for empty text.
    """
    if not isinstance(text, str):
        raise TypeError(f"the transcript must be a string, got {type(text).__name__}")
    decomposed = unicodedata.normalize("NFKD", text)
    foreign = sorted({c for c in decomposed if c.isalpha() and not c.isascii()})
    if foreign:
        scripts = sorted({unicodedata.name(c, "?").split()[0] for c in foreign})
        raise TextError(f"lip sync reads English text only (PocketSphinx's en-US model); the text has "
                        f"letters {''.join(foreign[:12])!r} of script(s) {', '.join(scripts)}")
    plain = "".join(c for c in decomposed if not unicodedata.combining(c)).lower()
    clauses = [_WORD.findall(part) for part in re.split(r"[,;:.!?]+(?:\s|$)", plain)]
    clauses = [[w.strip("'") for w in c if w.strip("'")] for c in clauses]
    clauses = [c for c in clauses if c]
    if not clauses:
        raise ValueError(f"the transcript {text[:60]!r} holds no words")
    return clauses


def check_words(words: list[str], lexicon: dict[str, tuple[str, ...]]) -> None:
    """Raise :class:`TextError` naming the words missing from ``lexicon`` (or calling the text
    non-English when most are missing)."""
    missing = sorted({w for w in words if w not in lexicon})
    if not missing:
        return
    if len(missing) > 0.5 * len(set(words)) and len(set(words)) >= 3:
        raise TextError(f"the text does not look like English: {len(missing)} of {len(set(words))} words "
                        f"are not in the en-US dictionary (e.g. {', '.join(missing[:6])}); lip sync "
                        "reads English only")
    raise TextError(f"words missing from the pronouncing dictionary: {', '.join(missing)}. Spell them "
                    "as they sound with dictionary words (numbers as words, e.g. 'twenty one')")


def _factors(phones: list[str], n_syll: int, function: bool, clause_final: bool) -> np.ndarray:
    """Klatt PRCNT factors of one word's phones."""
    isv = np.array([p in VOWELS for p in phones])
    f = np.ones(len(phones))
    vidx = np.flatnonzero(isv)
    last_v = vidx[-1] if len(vidx) else -1
    for i in range(len(phones)):
        if isv[i]:
            if clause_final and i == last_v:
                f[i] *= 1.4  # rule 2
            if i != last_v:
                f[i] *= 0.85  # rule 4
            if n_syll > 1:
                f[i] *= 0.8  # rule 5
            if i > 0 and isv[i - 1]:
                f[i] *= 0.7  # rule 10
        else:
            if i > 0:
                f[i] *= 0.85  # rule 6
            before = i > 0 and not isv[i - 1]
            after = i + 1 < len(phones) and not isv[i + 1]
            f[i] *= 0.5 if (before and after) else 0.7 if (before or after) else 1.0  # rule 10
        if function:
            f[i] *= 0.5 if isv[i] else 0.7  # rule 7
    return f


def text_phones(text: str, rate: float = 1.0, lexicon: dict | None = None) -> PhoneTrack:
    """Phones with Klatt-rule durations for an English ``text`` (see the module doc).

    Parameters
    ----------
    text : str
        English text; clauses split at punctuation get a pause between them.
    rate : float
        Speaking-rate factor in [0.1, 10]: durations are divided by it (1 = Klatt's rate).
    lexicon : dict, optional
        Word -> phones; by default the dictionary shipped with pocketsphinx.
    """
    rate = float(rate)
    if not 0.1 <= rate <= 10:  # 1e-9 asked for 10^10 frames; NaN fails too
        raise ValueError(f"rate must be a speaking-rate factor in [0.1, 10], got {rate}")
    lexicon = pronunciations() if lexicon is None else lexicon
    clauses = words_of(text)
    check_words([w for c in clauses for w in c], lexicon)
    labels, durs = ["SIL"], [_EDGE_PAUSE]
    for k, clause in enumerate(clauses):
        if k:
            labels.append("SIL")
            durs.append(_CLAUSE_PAUSE)
        for j, word in enumerate(clause):
            phones = list(lexicon[word])
            n_syll = sum(p in VOWELS for p in phones)
            f = _factors(phones, n_syll, word in _FUNCTION_WORDS, j == len(clause) - 1)
            inh, mn = np.array([KLATT_MS[p] for p in phones]).T
            labels += phones
            durs += list((mn + (inh - mn) * f) / 1000.0 / rate)
    labels.append("SIL")
    durs.append(_EDGE_PAUSE)
    end = np.cumsum(durs)
    return PhoneTrack(tuple(labels), np.concatenate([[0.0], end[:-1]]), end, "text")
