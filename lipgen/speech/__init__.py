"""Lip sync from speech: audio and text -> phones -> visemes -> activations -> mode coefficients.

- :mod:`~lipgen.speech.audio`: WAV reading (any common rate and format, as 16 kHz mono);
- :mod:`~lipgen.speech.phones`: phones with timings, English text to phones, Klatt durations;
- :mod:`~lipgen.speech.decode`: PocketSphinx forced alignment and phone recognition;
- :mod:`~lipgen.speech.visemes`: phones to visemes, visemes to activations by dynamics;
- :mod:`~lipgen.speech.lipsync`: the whole chain onto a model's modes;
- :mod:`~lipgen.speech.defaults`: the default lips, shipped precomputed, and the subject's
  motion on a model's nodes;
- :mod:`~lipgen.speech.outputs`: USD or USDZ (with the audio), npz, csv;
- :mod:`~lipgen.speech.score` and :mod:`~lipgen.speech.espeak`: accuracy against known timings.

PocketSphinx is imported only when audio is decoded (``pip install 'lipgen[speech]'``).
"""

from lipgen.speech.audio import Audio, AudioError, NoSpeechError, read_wav
from lipgen.speech.decode import align, phones_from_audio, recognize
from lipgen.speech.lipsync import LipSync, default_model, lipsync
from lipgen.speech.outputs import write_lipsync
from lipgen.speech.phones import PhoneTrack, TextError, text_phones
from lipgen.speech.visemes import activations

__all__ = ["Audio", "AudioError", "NoSpeechError", "read_wav", "LipSync", "lipsync", "default_model",
           "write_lipsync", "PhoneTrack", "TextError", "text_phones", "align", "recognize",
           "phones_from_audio", "activations"]
