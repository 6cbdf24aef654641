"""A speech recogniser with a word error rate: what the resident says → recognised text.

Elderly speakers and an untuned recogniser (the paper used Sphinx) make errors of
three kinds, each drawn per word with a seeded generator:

* **substitution** with a confusable word (``weather`` → ``whether``, ``time`` → ``dime``)
  or, when the word has no listed confusion, with a filler word;
* **deletion** (the word is lost);
* **insertion** of a filler word after it.

``word_error_rate`` is the expected number of errors per spoken word, split between
the three kinds by ``substitution/deletion/insertion`` weights (default 0.6/0.3/0.1,
roughly what is reported for conversational ASR).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List

import numpy as np

#: Common confusions of the domain's keywords (acoustically close words).
DEFAULT_CONFUSIONS: Dict[str, List[str]] = {
    "weather": ["whether", "feather", "wetter"],
    "time": ["dime", "tie", "thyme"],
    "yes": ["yet", "jess", "less"],
    "no": ["know", "now", "go"],
    "go": ["so", "no", "grow"],
    "nice": ["nine", "ice"],
    "thank": ["tank", "think"],
    "physio": ["fizzy", "video"],
    "forecast": ["for cast", "four cats"],
    "clock": ["block", "lock"],
}

#: Words a recogniser emits in noise or for mumbled speech. Short words dominate, and
#: some are keywords ("go", "no", "yes"): what the paper's Table 4 shows Sphinx hearing
#: ("pearl go to the that pretty good what", "go it eight a hello").
FILLERS = ["the", "a", "uh", "that", "hello", "it", "be", "pretty", "and", "what", "i", "to", "for", "eight",
           "go", "no", "yes", "good"]


@dataclass
class SpeechRecogniser:
    """Turns an utterance into recognised text with the configured error rate.

    Args:
        word_error_rate: expected errors per word, in [0, 1].
        confusions: word → acoustically confusable alternatives.
        seed: seed of the generator (every stochastic piece takes one).
    """

    word_error_rate: float = 0.2
    confusions: Dict[str, List[str]] = field(default_factory=lambda: dict(DEFAULT_CONFUSIONS))
    substitution: float = 0.6
    deletion: float = 0.3
    insertion: float = 0.1
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0.0 <= self.word_error_rate <= 1.0:
            raise ValueError(f"word_error_rate {self.word_error_rate} is not in [0, 1]")
        total = self.substitution + self.deletion + self.insertion
        if total <= 0:
            raise ValueError("substitution + deletion + insertion weights must be positive")
        self._kinds = np.array([self.substitution, self.deletion, self.insertion]) / total
        self.rng = np.random.default_rng(self.seed)

    def recognise(self, utterance: str) -> str:
        """The recogniser's text for ``utterance`` (lower case, words separated by spaces)."""
        out: List[str] = []
        for word in utterance.lower().split():
            if self.rng.random() >= self.word_error_rate:
                out.append(word)
                continue
            kind = self.rng.choice(3, p=self._kinds)
            bare = word.strip(".,?!")
            if kind == 0:
                options = self.confusions.get(bare) or FILLERS
                out.append(str(options[self.rng.integers(len(options))]))
            elif kind == 2:
                out.append(word)
                out.append(FILLERS[self.rng.integers(len(FILLERS))])
            # kind == 1: deleted
        return " ".join(out)
