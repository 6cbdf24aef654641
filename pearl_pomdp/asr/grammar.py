"""The recogniser's small language model, generated from a domain's ``keywords:``.

The paper's Sphinx "was run with a small vocabulary". We build that vocabulary and a
trigram model (pocketsphinx's own ARPA builder, :class:`pocketsphinx.lm.ArpaBoLM`)
from a corpus of three parts:

1. **keyword sentences**: every keyword phrase alone and in carrier phrases
   (:data:`CARRIERS`: ``"what {k} is it"``, ``"tell me the {k}"``, ``"{k} please"`` …),
   so a keyword is likely in the places people say it;
2. **filler sentences**: seeded random sequences of :data:`FILLER_WORDS`, common
   English words that are *not* keywords, and everyday :data:`CHATTER` ("hello pearl",
   "thank you") that contains no keyword. They are the garbage path: speech outside
   the domain is decoded as fillers, which the keyword filter maps to ``unknown``,
   instead of being forced onto the nearest keyword;
3. optional extra sentences (e.g. a deployment's own phrases).

Words missing from the CMU dictionary are spelt from dictionary pieces where
possible (``physiotherapy`` = ``physio`` + ``therapy``); the rest are left out of the
model and reported in :attr:`LanguageModel.missing`.
"""
from __future__ import annotations

import hashlib
import io
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Mapping, Optional, Sequence

import numpy as np

from pearl_pomdp.speech import tokens

__all__ = ["CARRIERS", "FILLER_WORDS", "LanguageModel", "build_language_model"]

#: Carrier phrases a keyword is spoken in; ``{k}`` is the keyword phrase.
CARRIERS = (
    "{k}", "{k} please", "{k} thank you", "oh {k}", "the {k}", "what is the {k}",
    "what is the {k} like", "what {k} is it", "tell me the {k}", "can you tell me the {k}", "give me the {k}",
    "i want the {k}", "i said {k}", "um {k}", "well {k}", "{k} pearl", "pearl {k}", "{k} i think",
    "will it {k} today", "is it going to {k}", "{k} today", "{k} tomorrow", "the {k} for tomorrow",
    "{k} to my appointment", "{k} now", "oh {k} please", "{k} all right",
)
#: Each keyword sentence is counted this many times: keywords are what the robot listens
#: for, so the model prefers them to a filler of similar sound.
KEYWORD_WEIGHT = 3

#: Common words that are not keywords: the garbage path (module doc). Chosen to cover
#: everyday requests and small talk of a care home, short words first.
FILLER_WORDS = (
    "a", "the", "i", "it", "is", "to", "and", "of", "in", "you", "me", "my", "that", "what", "this", "be", "can",
    "will", "for", "on", "at", "with", "do", "did", "say", "said", "tell", "give", "like", "is", "today",
    "tomorrow", "now", "then", "here", "there", "hello", "hi", "thank", "thanks", "nice", "good", "well", "oh",
    "um", "uh", "hmm", "pearl", "dear", "please", "how", "are", "am", "where", "when", "who", "why", "want",
    "need", "have", "has", "had", "some", "tea", "coffee", "water", "lunch", "dinner", "breakfast", "room",
    "door", "bed", "chair", "window", "light", "doctor", "nurse", "daughter", "son", "friend", "family", "name",
    "again", "more", "little", "very", "really", "know", "think", "see", "look", "come", "back", "up", "down",
    "out", "over", "later", "morning", "afternoon", "evening", "night", "day", "week", "fine", "tired", "cold",
    "warm", "hungry", "thirsty", "help", "wait", "sorry", "excuse", "robot", "music", "television", "book",
    "read", "sit", "sleep", "eat", "drink", "pills", "glasses", "phone", "call", "visit", "today's", "she",
    "he", "we", "they", "was", "were", "so", "but", "if", "about", "just", "all", "one", "two", "three",
    "therapy", "today", "lovely", "dear", "mine", "get", "put", "make", "keep", "not", "know", "pardon",
)

#: Everyday sentences that carry no request (greetings, thanks, small talk): part of the
#: garbage path, so that "hello pearl" is heard as itself and not as "no pearl".
CHATTER = (
    "hello pearl", "hello", "hi pearl", "good morning", "good morning pearl", "good afternoon", "good night",
    "thank you", "thank you pearl", "thanks", "that is nice", "that is lovely", "what did you say", "pardon",
    "sorry", "i am fine", "how are you", "where are my glasses", "i am tired", "hmm", "oh dear",
    "is that so", "very good", "that was nice", "see you later",
)

#: How many random filler sentences the corpus holds (about as many as keyword sentences).
FILLER_SENTENCES = 200


@dataclass
class LanguageModel:
    """An ARPA trigram model and its pronunciation dictionary.

    Attributes:
        arpa: the model in ARPA text format.
        dictionary: word → phones (CMU style, ``"P ER L"``) for every word of the model.
        keywords: the keyword phrases the model was built for (normalised).
        missing: words left out because no pronunciation could be found.
        digest: content hash of ``arpa`` + ``dictionary`` (cache key of recognitions).
    """

    arpa: str
    dictionary: Dict[str, str]
    keywords: List[str]
    missing: List[str] = field(default_factory=list)
    digest: str = ""


def _pronounce(word: str, lookup: Callable[[str], Optional[str]]) -> Optional[str]:
    """Phones of ``word``: from the dictionary, else spelt from two or three dictionary pieces."""
    phones = lookup(word)
    if phones:
        return phones
    bare = word.replace("'", "")
    if bare != word and lookup(bare):
        return lookup(bare)
    n = len(bare)
    for i in range(n - 2, 2, -1):  # longest head first: physio|therapy before phys|iotherapy
        head = lookup(bare[:i])
        if not head:
            continue
        tail = lookup(bare[i:])
        if tail:
            return f"{head} {tail}"
        for j in range(n - 2, i + 1, -1):
            mid, rest = lookup(bare[i:j]), lookup(bare[j:])
            if mid and rest:
                return f"{head} {mid} {rest}"
    return None


def keyword_sentences(keywords: Mapping[str, Sequence[str]]) -> List[str]:
    """Every keyword phrase in every carrier (normalised words)."""
    out: List[str] = []
    for phrases in keywords.values():
        for phrase in phrases:
            k = " ".join(tokens(phrase))
            if k:
                out.extend(c.format(k=k) for c in CARRIERS)
    return out


def filler_sentences(keywords: Mapping[str, Sequence[str]], count: int = FILLER_SENTENCES,
                     seed: int = 0) -> List[str]:
    """``count`` seeded random sentences of 1–6 filler words that contain no keyword phrase.

    A one-word keyword is never a filler; a word of a longer phrase may be ("me" of
    "take me"), as long as the whole phrase does not occur.
    """
    phrases = [tuple(tokens(p)) for ps in keywords.values() for p in ps]
    banned = {p[0] for p in phrases if len(p) == 1}
    words = sorted({w for w in FILLER_WORDS if w not in banned})
    rng = np.random.default_rng(seed)
    out = list(words)  # every filler alone once
    while len(out) < len(words) + count:
        n = int(rng.integers(1, 7))
        sentence = [words[i] for i in rng.integers(len(words), size=n)]
        if not any(_contains(sentence, p) for p in phrases):
            out.append(" ".join(sentence))
    return out


def _contains(words: Sequence[str], phrase: Sequence[str]) -> bool:
    n = len(phrase)
    return any(tuple(words[i:i + n]) == tuple(phrase) for i in range(len(words) - n + 1))


def build_language_model(keywords: Mapping[str, Sequence[str]], lookup: Callable[[str], Optional[str]],
                         extra_sentences: Sequence[str] = (), seed: int = 0) -> LanguageModel:
    """The domain's language model (module doc).

    Args:
        keywords: symbol → keyword phrases (a domain's ``keywords:`` section).
        lookup: word → phones or ``None`` (the decoder's CMU dictionary).
        extra_sentences: more sentences to put in the corpus.
        seed: seed of the filler sentences.

    Raises:
        ValueError: no keyword phrase has a pronounceable word.
    """
    from pocketsphinx.lm import ArpaBoLM

    keyword_words = {w for phrases in keywords.values() for p in phrases for w in tokens(p)}
    chatter = [c for c in CHATTER if not any(_contains(c.split(), tuple(tokens(p)))
                                              for ps in keywords.values() for p in ps)]
    corpus = keyword_sentences(keywords) * KEYWORD_WEIGHT + filler_sentences(keywords, seed=seed) + chatter * 2
    corpus += [" ".join(tokens(s)) for s in extra_sentences if tokens(s)]
    vocabulary = sorted({w for s in corpus for w in s.split()})
    dictionary, missing = {}, []
    for w in vocabulary:
        phones = _pronounce(w, lookup)
        if phones:
            dictionary[w] = phones
        else:
            missing.append(w)
    if not any(w in dictionary for w in keyword_words):
        raise ValueError("no keyword has a pronunciation in the recogniser's dictionary: "
                         + ", ".join(sorted(keyword_words)))
    if missing:
        gone = set(missing)
        corpus = [s for s in corpus if not gone & set(s.split())]
    lm = ArpaBoLM(text="\n".join(corpus) + "\n", add_start=True)
    lm.compute()
    buf = io.StringIO()
    lm.write(buf)
    arpa = buf.getvalue()
    h = hashlib.sha256(arpa.encode())
    for w in sorted(dictionary):
        h.update(f"{w}\t{dictionary[w]}\n".encode())
    phrases = sorted({" ".join(tokens(p)) for ps in keywords.values() for p in ps})
    return LanguageModel(arpa=arpa, dictionary=dictionary, keywords=phrases, missing=missing,
                         digest=h.hexdigest()[:16])
