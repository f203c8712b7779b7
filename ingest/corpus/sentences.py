"""English sentences for the synthetic speech corpus, and the CMU dictionary behind them.

:data:`SENTENCES` are hand-written for this project: phonetically rich, with many
phones that show on the lips (bilabials P B M, labiodentals F V, rounded vowels UW
OW W, open vowels AA AE AW). The first ten are emotionally neutral in content and
are the ones later spoken in all five emotions. Every word is in CMUdict (as shipped
with pocketsphinx), so forced alignment never has to guess a pronunciation.

:func:`generate_sentences` extends them with sentences from a small seeded grammar
whose every word is in CMUdict too. Generated sentences have 4 to 12 words, about
5.9 on average: 2.1 seconds at 165 words per minute (the paper's 1,326
utterances last 53 minutes, 2.4 s each).
"""

from __future__ import annotations

import bisect
import functools
import hashlib
import itertools
import logging
import random
import re
from dataclasses import dataclass
from pathlib import Path

from db.errors import DataError, ParameterError

logger = logging.getLogger(__name__)

SENTENCES: tuple[str, ...] = (
    # -- the ten spoken in every emotion: neutral, each covering many phones
    "The young boy took a brown bag of fresh cheese to the village market.",
    "We usually measure the water in the morning, before the pool opens.",
    "My father thought the old gray house needed a new roof.",
    "Please put the blue vase on the wooden shelf by the window.",
    "Four of the workers moved the heavy boxes away from the garage.",
    "Is the yellow bus going to stop outside the bank at noon?",
    "Both of them bought thick wool jackets for the long journey north.",
    "A quiet voice on the phone explained the new map of the city.",
    "The farmer pushed a cart of apples up the path toward the barn.",
    "Each Monday, we buy warm bread, fish, and fruit from the shop.",
    # -- statements, questions and exclamations full of lip-visible phones
    "Mom baked a plum pie for the whole family on Sunday.",
    "Why would anyone move a piano up five flights of stairs?",
    "Wow, the view from the top of the mountain was wonderful!",
    "Victor found a few old photos of his brother in a box.",
    "Could you open the window, please, before the meeting begins?",
    "The brave fox jumped over the fence and vanished into the woods.",
    "Bob and Pam went shopping for shoes at the mall.",
    "How many blue balloons floated above the crowd at the parade?",
    "Our neighbor grows huge pumpkins and ripe tomatoes behind his house.",
    "Five brown cows wandered slowly down the muddy path.",
    "Who left the empty milk bottles by the front door?",
    "The movie was about a pilot who flew over the ocean.",
    "I found my father's favorite pipe beneath a pile of papers.",
    "Stop the car, please, I think we passed the museum!",
    "Paul wore a woolen coat, a scarf, and heavy boots.",
    "What a beautiful rainbow appeared above the valley this morning!",
    "The small boat rocked on the waves of the bay.",
    "Maybe we should book a room near the old harbor.",
    "Every vote counts, so remember to visit the polls in November.",
    "Ruth moved to a cozy house by the river last spring.",
    "Do you know why the baby woke up so early?",
    "A powerful wind blew through the town and knocked down a few fences.",
    "Molly poured a bowl of soup and passed the bread to Tom.",
    "Have you ever seen a whale swim so close to the beach?",
    "My boss wants the report on his desk by Monday afternoon.",
    "Bring your umbrella, the clouds above the hills look very gloomy.",
    "The owl spotted a mouse moving among the fallen leaves.",
    "We spent the whole summer fishing and swimming at the lake.",
    "Oh no, the puppy chewed my new leather wallet!",
    "A loud noise woke up the boys at about four o'clock.",
    "Father often hums a familiar tune while he washes the pots.",
    "The police found a pair of muddy boots behind the barn.",
    "Would you prefer apple juice or a cup of warm cocoa?",
    "Vivian bought a purple blouse, a pair of gloves, and a belt.",
    "The food at the new cafe was cheap but very good.",
    "Mary had a fever, so she stayed home from work on Friday.",
    "Bubbles floated up from the bottom of the pond.",
    "Put the money in your pocket before you board the bus.",
    "The mayor announced a plan to build more public parks.",
    "How often do you go jogging along the beach?",
    "Look, the moon is rising above the roofs of the town!",
    "The farmer's wife fed the ducks and the goats every evening.",
    "Many people believe that a full moon brings bad luck.",
    "The fireman climbed the ladder and rescued a frightened cat.",
    "Tom's mother plays the violin with a famous orchestra.",
    "We must move the furniture before the painters arrive.",
    "Frank pulled a rope and the heavy boat moved forward.",
    "Who bought all the blueberries at the farm market?",
    "The wolf howled at the moon from the top of the hill.",
    "The pleasure of a good book is a treasure for life.",
    "Beware, the bridge above the deep pool is very old!",
    "Both brothers joined the army when they were twenty.",
    "Pour the boiling water over the coffee very slowly.",
    "A warm breeze moved through the palms along the coast.",
    "Why was the museum closed on a busy Monday morning?",
    "The choir sang a joyful song about peace and hope.",
    "Her casual beige jacket was the usual choice for such a job.",
    "The evening television news showed a vision of the future.",
    "Joy, the cheerful cook, enjoyed boiling oysters for lunch.",
    "Wow, what a beautiful view of the bay!",
    "Please move the boxes off the porch.",
    "Who wrote this funny poem about bubbles?",
    "Bobby bought five warm muffins for breakfast.",
    "Whoever found my purple umbrella, thank you so much!",
)

# --------------------------------------------------------------------------- CMUdict

_STRESS = re.compile(r"\d")
_VARIANT = re.compile(r"\(\d+\)$")
_WORD = re.compile(r"[a-z0-9]+(?:'[a-z0-9]+)*")


def _cmudict_path() -> Path:
    try:
        from pocketsphinx import get_model_path
    except ImportError as exc:  # pragma: no cover - pocketsphinx is a dependency
        raise DataError(f"CMUdict: pocketsphinx is not installed ({exc})") from exc
    return Path(get_model_path()) / "en-us" / "cmudict-en-us.dict"


@functools.lru_cache(maxsize=1)
def cmudict() -> dict[str, list[tuple[str, ...]]]:
    """The CMU pronouncing dictionary shipped with pocketsphinx.

    Returns
    -------
    dict of str to list of tuple of str
        Lower-case word to its pronunciations, first the main one, then the
        variants (``word(2)`` ...). Phones are ARPAbet without stress digits. The
        dict is cached and shared: do not modify it.

    Raises
    ------
    DataError
        If the dictionary file is missing or unreadable.
    """
    path = _cmudict_path()
    entries: dict[str, list[tuple[str, ...]]] = {}
    try:
        with open(path, encoding="utf-8") as handle:
            for line in handle:
                fields = line.split()
                if len(fields) < 2 or fields[0].startswith(";;;"):
                    continue
                word = _VARIANT.sub("", fields[0].lower())
                entries.setdefault(word, []).append(
                    tuple(_STRESS.sub("", phone) for phone in fields[1:])
                )
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"cannot read CMUdict {path}: {exc}") from exc
    if not entries:
        raise DataError(f"CMUdict is empty: {path}")
    logger.debug("loaded CMUdict %s: %d words", path, len(entries))
    return entries


def words(text: str) -> list[str]:
    """Split text into lower-case words as CMUdict spells them.

    Punctuation is dropped; apostrophes inside a word are kept (``o'clock``,
    ``father's``), typographic ones (’) are read as ``'``.

    Parameters
    ----------
    text : str
        Any English text.

    Returns
    -------
    list of str
        The words, in order.
    """
    if not isinstance(text, str):
        raise ParameterError(f"text: expected str, got {type(text).__name__}")
    return _WORD.findall(text.lower().replace("\u2019", "'"))


# --------------------------------------------------------------------------- grammar

#: Word lists of the grammar's slots; every slot holds one word. Nouns and adjectives
#: that can follow "a" start with a consonant sound.
_SLOTS: dict[str, tuple[str, ...]] = {
    "name": (
        "bob", "pam", "paul", "molly", "mary", "frank", "ruth", "tom", "victor", "vivian",
        "peter", "martha", "phil", "bruce", "beth", "walter", "paula", "ben", "fiona",
        "maud", "owen", "wendy",
    ),
    "noun": (
        "farmer", "baker", "pilot", "mother", "father", "woman", "boy", "plumber", "barber",
        "fisherman", "painter", "teacher", "mayor", "neighbor", "poet", "lawyer", "brother",
        "driver", "banker", "waiter", "nephew", "cowboy", "mover", "porter",
    ),
    "kind": (
        "young", "busy", "brave", "polite", "patient", "famous", "cheerful", "wise", "gentle",
        "proud", "calm", "funny", "thoughtful", "bored", "sleepy",
    ),
    "adj": (
        "brown", "blue", "big", "warm", "small", "heavy", "purple", "yellow", "smooth",
        "wooden", "shiny", "pretty", "fancy", "cheap", "new", "huge", "tiny", "woolen",
        "plastic", "golden", "silver", "broken", "dusty", "muddy", "velvet", "paper", "beige",
    ),
    "thing": (
        "box", "boat", "map", "bottle", "pumpkin", "basket", "violin", "wallet", "blanket",
        "mirror", "hammer", "puppet", "bucket", "vase", "photo", "jacket", "shovel",
        "football", "bowl", "pillow", "balloon", "banjo", "bicycle", "pot", "kettle", "mop",
        "broom", "blouse", "bench", "couch", "sofa", "trumpet", "wheel", "barrel", "parcel",
        "notebook", "coin", "toy",
    ),
    "verbed": (
        "bought", "found", "moved", "brought", "painted", "washed", "pushed", "fixed", "sold",
        "carried", "opened", "dropped", "borrowed", "packed", "folded", "polished", "grabbed",
        "saw", "made", "wrapped", "covered", "loaded", "lifted", "weighed", "measured",
    ),
    "verb": (
        "buy", "find", "move", "bring", "paint", "wash", "push", "fix", "sell", "carry",
        "open", "drop", "borrow", "pack", "fold", "polish", "grab", "see", "make", "wrap",
        "cover", "load", "lift", "weigh", "measure",
    ),
    "prep": ("near", "behind", "beside", "by", "outside", "inside", "below", "above"),
    "place": (
        "harbor", "bridge", "house", "market", "office", "park", "village", "museum", "beach",
        "valley", "window", "barn", "garden", "farm", "pool", "kitchen", "mall", "chapel",
        "factory", "fountain", "cabin", "stable", "tower", "palace", "bakery", "cottage",
        "meadow", "forest", "shop", "garage",
    ),
    "adverb": (
        "slowly", "quietly", "proudly", "calmly", "carefully", "gently", "boldly", "firmly",
        "swiftly", "promptly", "politely", "patiently", "bravely",
    ),
    "poss": ("my", "his", "her", "our", "your", "their"),
    "time": ("yesterday", "today", "tonight", "again", "twice", "early", "later"),
    "day": ("monday", "tuesday", "wednesday", "thursday", "friday", "saturday", "sunday"),
}

#: Templates and their weights. A word is a ``{slot}`` or a literal, either with
#: trailing punctuation. Templates of equal length and punctuation differ at some
#: position in words no slot shares, so no sentence comes from two templates.
_TEMPLATE_SPECS: tuple[tuple[str, float], ...] = (
    ("{name} {verbed} {poss} {thing}.", 4.0),  # 4 words
    ("{name} {verbed} the {thing} {time}.", 4.0),  # 5
    ("{name}, please {verb} the {adj} {thing}.", 1.5),  # 6
    ("the {noun} {verbed} a {adj} {thing}!", 1.5),  # 6
    ("the {kind} {noun} {verbed} the {thing}.", 1.5),  # 6
    ("{poss} {noun} {verbed} a {adj} {thing} {time}.", 1.0),  # 7
    ("where did {name} {verb} the {adj} {thing}?", 1.0),  # 7
    ("{name} {verbed} a {adj} {thing} for the {noun}.", 0.6),  # 8
    ("did the {noun} {verb} the {thing} on {day}?", 0.6),  # 8
    ("{name} {adverb} {verbed} the {adj} {thing} {prep} the {place}.", 0.4),  # 9
    ("the {kind} {noun} {verbed} a {thing} {prep} the {place}.", 0.4),  # 9
    ("why did the {noun} {verb} a {thing} {prep} the {place}?", 0.3),  # 10
    ("on {day}, the {noun} {verbed} a {adj} {thing} {prep} the {place}.", 0.2),  # 11
    ("the {kind} {noun} {adverb} {verbed} the {thing} {prep} the {place} on {day}.", 0.2),  # 12
)

#: Slots of proper nouns, capitalised wherever they stand.
_PROPER = frozenset({"name", "day"})

_TOKEN = re.compile(r"^(?:\{(?P<slot>[a-z]+)\}|(?P<word>[a-z']+))(?P<suffix>[^a-z'{}]*)$")


@dataclass(frozen=True)
class _Part:
    """One word position of a template: a slot or a literal word, then punctuation."""

    slot: str | None
    word: str
    suffix: str

    @property
    def choices(self) -> tuple[str, ...]:
        return _SLOTS[self.slot] if self.slot is not None else (self.word,)


@dataclass(frozen=True)
class _Template:
    parts: tuple[_Part, ...]
    weight: float

    @property
    def size(self) -> int:
        """Number of distinct sentences the template makes."""
        size = 1
        for part in self.parts:
            size *= len(part.choices)
        return size

    def render(self, index: int) -> str:
        """The sentence number ``index`` (0 <= index < size), mixed-radix over the slots."""
        out = []
        for part in reversed(self.parts):
            index, pick = divmod(index, len(part.choices))
            word = part.choices[pick]
            out.append((word.title() if part.slot in _PROPER else word) + part.suffix)
        text = " ".join(reversed(out))
        return text[0].upper() + text[1:]

    def matches(self, sentence: str) -> bool:
        """True if the template can produce ``sentence``."""
        tokens = sentence.split()
        if len(tokens) != len(self.parts):
            return False
        for token, part in zip(tokens, self.parts, strict=True):
            word = token.rstrip(".,!?;:").lower()
            if token[len(word):] != part.suffix or word not in part.choices:
                return False
        return True


def _parse(spec: str, weight: float) -> _Template:
    parts = []
    for token in spec.split():
        match = _TOKEN.match(token)
        if match is None or (match["slot"] is not None and match["slot"] not in _SLOTS):
            raise AssertionError(f"bad template token {token!r} in {spec!r}")
        parts.append(_Part(match["slot"], match["word"] or "", match["suffix"]))
    return _Template(tuple(parts), weight)


_TEMPLATES: tuple[_Template, ...] = tuple(_parse(spec, w) for spec, w in _TEMPLATE_SPECS)

_MASK64 = (1 << 64) - 1


def _mix(value: int, key: int, round_: int) -> int:
    """A 64-bit integer hash (splitmix64 finaliser) of value, key and round."""
    x = (value * 0x9E3779B97F4A7C15 + key + round_ * 0xD1B54A32D192ED03) & _MASK64
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & _MASK64
    return x ^ (x >> 31)


def _shuffled_index(i: int, size: int, key: int) -> int:
    """Element ``i`` of a keyed pseudo-random permutation of ``range(size)``.

    A four-round Feistel network on the smallest even bit width covering ``size``,
    cycle-walked back into range: a bijection, computed without storing anything.
    """
    bits = max(2, (size - 1).bit_length())
    bits += bits % 2
    half = bits // 2
    low = (1 << half) - 1
    x = i
    while True:
        left, right = x >> half, x & low
        for round_ in range(4):
            left, right = right, left ^ (_mix(right, key, round_) & low)
        x = (left << half) | right
        if x < size:
            return x


def _key(seed: int, template: int) -> int:
    digest = hashlib.blake2b(f"{seed}:{template}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little")


@functools.lru_cache(maxsize=1)
def _collisions() -> frozenset[str]:
    """The hand-written sentences the grammar could also produce (skipped when drawn)."""
    return frozenset(s for s in SENTENCES if any(t.matches(s) for t in _TEMPLATES))


def max_sentences() -> int:
    """The largest ``n`` :func:`generate_sentences` accepts: all sentences it can make."""
    grammar = sum(t.size for t in _TEMPLATES)
    return len(SENTENCES) + grammar - len(_collisions())


def generate_sentences(n: int, *, seed: int = 0) -> list[str]:
    """``n`` distinct sentences: :data:`SENTENCES` first, then from a seeded grammar.

    Parameters
    ----------
    n : int
        How many sentences, 1 <= n <= :func:`max_sentences`.
    seed : int, optional
        Seed of the generated part. The result is a function of ``(n, seed)`` only,
        and ``generate_sentences(m, seed=s)`` is a prefix of
        ``generate_sentences(n, seed=s)`` for ``m <= n``.

    Returns
    -------
    list of str
        ``SENTENCES[:n]``, followed (if ``n > len(SENTENCES)``) by grammar sentences of
        4 to 12 words, all distinct.

    Raises
    ------
    ParameterError
        If ``n`` or ``seed`` is not an int, or ``n`` is out of range.
    """
    if isinstance(n, bool) or not isinstance(n, int):
        raise ParameterError(f"n: expected an int, got {n!r}")
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ParameterError(f"seed: expected an int, got {seed!r}")
    limit = max_sentences()
    if not 1 <= n <= limit:
        raise ParameterError(f"n: expected 1 <= n <= {limit}, got {n}")
    out = list(SENTENCES[:n])
    if n <= len(SENTENCES):
        return out

    # Pick a template by weight, then take its next sentence in a keyed permutation
    # of all its sentences: no repeats within a template, none across templates.
    rng = random.Random(seed)
    keys = [_key(seed, i) for i in range(len(_TEMPLATES))]
    used = [0] * len(_TEMPLATES)
    skip = _collisions()
    while len(out) < n:
        open_ = [i for i, t in enumerate(_TEMPLATES) if used[i] < t.size]
        bounds = list(itertools.accumulate(_TEMPLATES[i].weight for i in open_))
        i = open_[bisect.bisect_right(bounds, rng.random() * bounds[-1])]
        template = _TEMPLATES[i]
        sentence = template.render(_shuffled_index(used[i], template.size, keys[i]))
        used[i] += 1
        if sentence not in skip:
            out.append(sentence)
    return out
