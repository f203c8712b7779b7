"""The hand-written corpus sentences, the sentence grammar and the CMUdict helpers."""

from __future__ import annotations

import statistics
from collections import Counter
from itertools import combinations

import pytest

from db.errors import ParameterError
from ingest.corpus import sentences as mod
from ingest.corpus.sentences import (
    SENTENCES,
    cmudict,
    generate_sentences,
    max_sentences,
    words,
)
from ingest.speech.phones import CONSONANTS, VOWELS

CMU_PHONES = frozenset(VOWELS + CONSONANTS)


def _phone_counts(texts) -> Counter:
    counts: Counter = Counter()
    lexicon = cmudict()
    for text in texts:
        for word in words(text):
            counts.update(lexicon[word][0])
    return counts


def test_cmudict_basics():
    lexicon = cmudict()
    assert len(lexicon) > 100_000
    assert lexicon["the"][0] == ("DH", "AH")
    assert ("R", "IY", "D") in lexicon["read"]  # the read(2) variant
    assert "read(2)" not in lexicon
    assert all(phone in CMU_PHONES for phone in lexicon["measure"][0])
    assert cmudict() is lexicon  # cached


def test_words():
    assert words("Stop the car, please, I think we passed the museum!") == [
        "stop", "the", "car", "please", "i", "think", "we", "passed", "the", "museum",
    ]
    assert words("Four o'clock, father’s pipe... 'quoted'") == [
        "four", "o'clock", "father's", "pipe", "quoted",
    ]
    assert words("") == []
    with pytest.raises(ParameterError, match="text"):
        words(None)


def test_sentences_shape():
    assert len(SENTENCES) >= 60
    assert len(set(SENTENCES)) == len(SENTENCES)
    for sentence in SENTENCES:
        assert 6 <= len(words(sentence)) <= 14, sentence
        assert sentence[0].isupper() and sentence[-1] in ".?!", sentence
    ends = Counter(s[-1] for s in SENTENCES)
    assert ends["?"] >= 5 and ends["!"] >= 5
    assert sum("," in s for s in SENTENCES) >= 5


def test_sentences_in_cmudict():
    lexicon = cmudict()
    missing = {w for s in SENTENCES for w in words(s) if w not in lexicon}
    assert not missing


def test_sentences_cover_all_phones():
    counts = _phone_counts(SENTENCES)
    assert set(counts) == CMU_PHONES
    assert min(counts[p] for p in CMU_PHONES) >= 5, counts.most_common()[-5:]
    first = _phone_counts(SENTENCES[:10])
    assert len(set(first) & CMU_PHONES) >= 35


def test_sentences_favour_lip_visible_phones():
    counts = _phone_counts(SENTENCES)
    for phone in ("P", "B", "M", "F", "V", "UW", "OW", "W", "AA", "AE", "AW"):
        assert counts[phone] >= 30, phone


def test_generate_prefix_and_determinism():
    assert generate_sentences(1) == [SENTENCES[0]]
    assert generate_sentences(10) == list(SENTENCES[:10])
    assert generate_sentences(len(SENTENCES)) == list(SENTENCES)
    many = generate_sentences(1500)
    assert many[: len(SENTENCES)] == list(SENTENCES)
    assert generate_sentences(1500) == many
    assert generate_sentences(700) == many[:700]  # prefix-stable in n
    other = generate_sentences(1500, seed=7)
    assert other[: len(SENTENCES)] == list(SENTENCES)
    assert other[len(SENTENCES):] != many[len(SENTENCES):]
    assert generate_sentences(1500, seed=7) == other


def test_generated_sentences():
    many = generate_sentences(2000)
    assert len(set(many)) == 2000
    generated = many[len(SENTENCES):]
    lexicon = cmudict()
    missing = {w for s in generated[:1500] for w in words(s) if w not in lexicon}
    assert not missing
    lengths = [len(words(s)) for s in generated]
    assert min(lengths) >= 4 and max(lengths) <= 12
    # Short, as the paper's utterances are (1,326 in 53 minutes): about 5.9 words,
    # 2.1 s at 165 words per minute.
    assert 5.5 <= statistics.mean(lengths) <= 6.3
    for sentence in generated:
        assert sentence[0].isupper() and sentence[-1] in ".?!", sentence


def test_grammar_words_in_cmudict():
    lexicon = cmudict()
    for slot, choices in mod._SLOTS.items():
        assert len(set(choices)) == len(choices), slot
        assert all(w in lexicon and " " not in w for w in choices), slot
    for template in mod._TEMPLATES:
        for part in template.parts:
            assert part.slot is not None or part.word in lexicon


def test_grammar_templates_are_disjoint():
    """Same-shaped templates differ at some position in words no slot shares."""
    for a, b in combinations(mod._TEMPLATES, 2):
        if [p.suffix for p in a.parts] != [p.suffix for p in b.parts]:
            continue
        assert any(
            not set(pa.choices) & set(pb.choices) for pa, pb in zip(a.parts, b.parts, strict=True)
        ), (a, b)


def test_grammar_does_not_remake_hand_written_sentences():
    assert mod._collisions() == frozenset()
    sample = generate_sentences(300)[len(SENTENCES):]
    assert all(any(t.matches(s) for t in mod._TEMPLATES) for s in sample)


@pytest.mark.parametrize("size", [1, 2, 3, 5, 17, 1000, 4099])
def test_shuffled_index_is_a_permutation(size):
    assert sorted(mod._shuffled_index(i, size, 12345) for i in range(size)) == list(range(size))


def test_max_sentences():
    assert max_sentences() >= 2000
    assert max_sentences() == len(SENTENCES) + sum(t.size for t in mod._TEMPLATES)


@pytest.mark.parametrize("n", [0, -3, 1.5, "10", True, None])
def test_generate_bad_n(n):
    with pytest.raises(ParameterError, match="n"):
        generate_sentences(n)


def test_generate_bad_seed_and_too_many():
    with pytest.raises(ParameterError, match="seed"):
        generate_sentences(5, seed=1.5)
    with pytest.raises(ParameterError, match="n"):
        generate_sentences(max_sentences() + 1)
