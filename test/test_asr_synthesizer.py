"""espeak-ng through ctypes: voices, rates, and the errors of bad input."""
from __future__ import annotations

import numpy as np
import pytest

import espeakng_loader  # noqa: F401  (a missing install fails, it is not skipped)

from pearl_pomdp.asr.synthesizer import VOICES, SynthesisError, Voice, get_voice, synthesize  # noqa: E402


def test_synthesis_is_16_khz_speech_and_slower_voices_are_longer():
    clear = synthesize("what time is it", "clear")
    slow = synthesize("what time is it", "slow")
    assert clear.dtype == np.int16 and 0.5 * 16000 < len(clear) < 2.5 * 16000
    assert len(slow) > 1.2 * len(clear)
    assert np.sqrt(np.mean(clear.astype(float) ** 2)) > 300  # audible, not silence
    # espeak-ng keeps a little state between calls (a few samples differ after another voice).
    assert abs(len(synthesize("what time is it", "clear")) - len(clear)) < 0.01 * len(clear)


def test_every_preset_speaks():
    for name in VOICES:
        assert len(synthesize("yes", name)) > 1600, name


def test_empty_text_is_no_audio_and_bad_input_is_one_clear_error():
    assert len(synthesize("   ")) == 0
    with pytest.raises(SynthesisError, match="unknown voice 'robot'"):
        synthesize("yes", "robot")
    with pytest.raises(SynthesisError, match="espeak-ng has no voice 'xx-nowhere'"):
        synthesize("yes", {"name": "xx-nowhere"})
    with pytest.raises(SynthesisError, match="rate 5 is not in"):
        Voice("en-us", rate=5)
    with pytest.raises(SynthesisError, match="unknown field"):
        get_voice({"name": "en-us", "speed": 3})
    with pytest.raises(SynthesisError, match="longer than 2000"):
        synthesize("a " * 1500)
