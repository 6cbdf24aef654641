"""Real speech for Pearl, ROS-free: recogniser, synthesiser, noise and the measured channel.

* :mod:`~pearl_pomdp.asr.recognizer` — pocketsphinx (CMU Sphinx) on a language model
  generated from the domain's keywords, with a filler path; VAD utterance segmentation.
* :mod:`~pearl_pomdp.asr.synthesizer` — espeak-ng through ctypes; named resident voices.
* :mod:`~pearl_pomdp.asr.audio` — 16 kHz PCM checks, WAV files, noise at a given SNR.
* :mod:`~pearl_pomdp.asr.channel` — ``pearl calibrate-speech``: the measured confusion
  P(recognised symbol | meant symbol, SNR) and a fast sampler from it.

pocketsphinx and espeakng-loader are imported when first used, so importing this
package costs nothing and a missing library gives one clear error when needed.
See docs/speech.md.
"""
from pearl_pomdp.asr.audio import SAMPLE_RATE, AudioError

__all__ = ["SAMPLE_RATE", "AudioError"]
