"""The babble noise: several other people talking in the corridor, specified from its sources.

Why babble: a nursing-home corridor or day room is not white noise. What is heard there is
other residents and staff talking and a television — speech-shaped noise made of real
words, which is what makes a keyword recogniser *insert* words (hear "no" or "go" that
nobody said to the robot). Insertions are what a clarification question guards against,
so the study's noise axis has this kind beside white noise (docs/speech.md § Noise,
docs/study.md § The noise-kind axis).

The track, fixed before any study ran on it (issue 23):

* **Talkers**: :data:`TALKERS` — six espeak-ng voices (three male, three female; US and
  British), none of them a resident preset of :data:`~pearl_pomdp.asr.synthesizer.VOICES`,
  so the babble is other people. Six because babble of about six or more talkers no longer
  lets single voices be followed and masks consonants about as well as any babble does
  (Simpson & Cooke 2005, "Consonant identification in N-talker babble is a nonmonotonic
  function of N", JASA 118(5)); fewer talkers leave gaps in which a robot hears one clear
  stranger.
* **What they say**: :data:`SENTENCES` — the IEEE "Harvard" sentences, lists 1 and 2, in
  order (IEEE Recommended Practice for Speech Quality Measurements, 1969): everyday English
  chosen by the standard's authors for phonetic balance, not by us for what the robot's
  keywords are. Talker ``i`` reads sentences ``i, i+6, i+12, …`` with a 0.4 s pause after
  each, as in a conversation; its stream is repeated to the longest talker's length.
* **Level**: every talker at the same RMS (people at a similar distance from the robot); the
  sum is scaled to the SNR asked of :func:`~pearl_pomdp.asr.audio.mix_at_snr`, so the level
  is the study's SNR axis. The levels that axis covers come from measured ones: nursing-home
  floors and nurses' stations 55–70 dB ("What do patterns of noise in a teaching hospital
  and nursing home suggest?", Noise & Health 2007, 9(35):31–34, doi:10.4103/1463-1741.36977),
  bedrooms of five long-term-care facilities 47–59 dBA by day ("Sound environment of
  bedrooms in typical long-term care facilities in China", Kunming), a
  conversational voice about 55–60 dBA at 1 m, raised in noise (Pearsons, Bennett & Fidell
  1977, *Speech levels in various noise environments*, EPA-600/1-77-025). A resident 1 m from
  the robot in a 50–55 dB room is therefore at about 5–10 dB SNR, in a busy corridor at 0–5 dB;
  a quiet bedroom at 20–30 dB.

:data:`TRACK_ID` names this specification: it is part of every babble trial's cache key
(``pearl_pomdp.asr.channel``), so a changed track can never reuse an old result.
"""
from __future__ import annotations

import hashlib
from functools import lru_cache
from typing import Tuple

import numpy as np

__all__ = ["SENTENCES", "TALKERS", "PAUSE_SECONDS", "TRACK_ID", "babble_track"]

#: IEEE Harvard sentences, lists 1 and 2, in the standard's order.
SENTENCES: Tuple[str, ...] = (
    "The birch canoe slid on the smooth planks.",
    "Glue the sheet to the dark blue background.",
    "It's easy to tell the depth of a well.",
    "These days a chicken leg is a rare dish.",
    "Rice is often served in round bowls.",
    "The juice of lemons makes fine punch.",
    "The box was thrown beside the parked truck.",
    "The hogs were fed chopped corn and garbage.",
    "Four hours of steady work faced us.",
    "A large size in stockings is hard to sell.",
    "The boy was there when the sun rose.",
    "A rod is used to catch pink salmon.",
    "The source of the huge river is the clear spring.",
    "Kick the ball straight and follow through.",
    "Help the woman get back to her feet.",
    "A pot of tea helps to pass the evening.",
    "Smoky fires lack flame and heat.",
    "The soft cushion broke the man's fall.",
    "The salt breeze came across from the sea.",
    "The girl at the booth sold fifty bonds.",
)
#: (espeak-ng voice, words per minute, pitch) of each talker: none is a resident's voice.
TALKERS: Tuple[Tuple[str, int, int], ...] = (
    ("en-us+m1", 165, 45),
    ("en-us+f1", 170, 60),
    ("en-gb-x-rp+m4", 160, 40),
    ("en-us+f4", 175, 55),
    ("en-us+m7", 155, 35),
    ("en-gb-x-rp+f3", 165, 65),
)
#: Silence after each sentence of a talker (s).
PAUSE_SECONDS = 0.4
#: The specification's identity (part of every babble trial's cache key).
TRACK_ID = "babble:" + hashlib.sha256(repr((SENTENCES, TALKERS, PAUSE_SECONDS, 1)).encode()).hexdigest()[:12]


@lru_cache(maxsize=1)
def babble_track() -> np.ndarray:
    """The six talkers summed (float samples at 16 kHz, about 11 s; built once per process, ~2 s)."""
    from pearl_pomdp.asr.audio import SAMPLE_RATE
    from pearl_pomdp.asr.synthesizer import synthesize

    pause = np.zeros(int(round(PAUSE_SECONDS * SAMPLE_RATE)))
    streams = []
    for i, (name, rate, pitch) in enumerate(TALKERS):
        parts = []
        for text in SENTENCES[i::len(TALKERS)]:
            parts += [synthesize(text, {"name": name, "rate": rate, "pitch": pitch}).astype(np.float64), pause]
        stream = np.concatenate(parts)
        streams.append(stream / np.sqrt(np.mean(stream ** 2)))   # every talker at the same RMS
    n = max(len(s) for s in streams)
    track = np.zeros(n)
    for s in streams:
        track += np.resize(s, n)          # a shorter talker starts her first sentence again
    return track * (3000.0 / np.sqrt(np.mean(track ** 2)))   # int16 scale; mix_at_snr sets the level
