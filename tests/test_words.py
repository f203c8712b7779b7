"""Word alignments beside a clip: GRID ``.align``, TextGrid word tiers, and phones aligned
inside the words (issue #14)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from db.errors import DataError, ParameterError
from ingest.formats.words import (
    GRID_UNIT,
    WordSegment,
    read_grid_align,
    read_textgrid_words,
    word_tier,
)
from ingest.readers import discover, load
from ingest.speech import ctc
from ingest.speech.espeak import Voice, speak
from ingest.speech.g2p import pronounce
from ingest.speech.phones import SILENCE
from ingest.speech.words import align_words

#: The first lines of GRID s1's bbaf2n.align as shipped (CRLF, 1/25000 s).
GRID_ALIGN = (b"0 23750 sil\r\n23750 29500 bin\r\n29500 34000 blue\r\n34000 35500 at\r\n"
              b"35500 41000 f\r\n41000 47250 two\r\n47250 53000 now\r\n53000 74500 sil\r\n")

#: A one-tier TextGrid in Praat's short text format: a pause, then "open window".
WORD_TEXTGRID = '''File type = "ooTextFile"
Object class = "TextGrid"

0
1.5
<exists>
1
"IntervalTier"
"Words"
0
1.5
3
0
0.4
""
0.4
0.9
"open"
0.9
1.5
"window"
'''


def _word_textgrid(path):
    path.write_text(WORD_TEXTGRID)


def test_grid_align(tmp_path):
    path = tmp_path / "bbaf2n.align"
    path.write_bytes(GRID_ALIGN)
    words = read_grid_align(path)
    assert [w.word for w in words] == [None, "bin", "blue", "at", "f", "two", "now", None]
    assert words[1] == WordSegment("bin", pytest.approx(0.95), pytest.approx(1.18))
    assert words[-1].end == pytest.approx(74500 * GRID_UNIT) == pytest.approx(2.98)
    # frame = value / 1000 at 25 fps
    assert words[2].start * 25 == pytest.approx(29.5)


def test_grid_align_errors(tmp_path):
    bad = {
        "empty": b"",
        "not before": b"0 100 sil\r\n100 90 bin\r\n",
        "overlaps": b"0 100 sil\r\n50 200 bin\r\n",
        "expected 'start end word'": b"0 100\r\n",
        "integers": b"0 1.5 bin\r\n",
        "no words": b"0 100 sil\r\n",
    }
    path = tmp_path / "bad.align"
    for message, content in bad.items():
        path.write_bytes(content)
        with pytest.raises(DataError, match=message):
            read_grid_align(path)
    with pytest.raises(DataError, match="not found"):
        read_grid_align(tmp_path / "absent.align")


def test_textgrid_word_tier(tmp_path):
    path = tmp_path / "clip.TextGrid"
    _word_textgrid(path)
    assert word_tier(path) == "Words"
    words = read_textgrid_words(path)
    assert words == [WordSegment(None, 0.0, 0.4), WordSegment("open", 0.4, 0.9),
                     WordSegment("window", 0.9, 1.5)]
    with pytest.raises(DataError, match="no word interval tier 'phones'"):
        read_textgrid_words(path, tier="phones")


def _word_intervals(utterance, words):
    """Word intervals of eSpeak speech spoken with long gaps: its non-SIL runs."""
    runs, current = [], None
    for p in utterance.phones:
        if p.phone == SILENCE:
            current = None
        elif current is None:
            current = [p.start, p.end]
            runs.append(current)
        else:
            current[1] = p.end
    assert len(runs) == len(words)
    return [WordSegment(w, s, e) for w, (s, e) in zip(words, runs, strict=True)]


def test_align_words_keeps_word_boundaries():
    words = ["open", "window", "bottle"]
    utterance = speak(" ".join(words), Voice(word_gap=30))  # 300 ms between words
    given = _word_intervals(utterance, words)
    segments, n_even = align_words(utterance.audio, utterance.sample_rate, given)
    assert n_even == 0
    assert segments[0].start == 0 and segments[-1].end == pytest.approx(utterance.duration)
    starts = {round(s.start, 6) for s in segments}
    for word in given:  # every word boundary is a phone boundary ...
        assert round(word.start, 6) in starts
        inside = [s.phone for s in segments if word.start - 1e-6 <= s.start < word.end - 1e-6]
        # ... and the phones inside are the word's (CMUdict's first pronunciation here)
        assert inside == list(pronounce(word.word)), word
    gaps = [s for s in segments if s.phone == SILENCE]
    assert len(gaps) == len(words) + 1  # before, between and after the words


def test_align_words_spreads_a_word_too_short_for_its_phones():
    utterance = speak("strengths", Voice())
    start = utterance.phones[1].start
    segments, n_even = align_words(utterance.audio, utterance.sample_rate,
                                   [WordSegment("strengths", start, start + 0.06)])
    assert n_even == 1
    inside = [s for s in segments if s.phone != SILENCE]
    assert [s.phone for s in inside] == list(pronounce("strengths"))
    assert inside[0].start == pytest.approx(start) and inside[-1].end == pytest.approx(start + 0.06)
    with pytest.raises(ParameterError, match="only silence"):
        align_words(utterance.audio, utterance.sample_rate, [WordSegment(None, 0.0, 0.5)])


def _landmark_folder(root, name="clip", seconds=2.0, fps=25.0):
    """A landmark clip folder of a still canonical face with a tone as its speech."""
    from ingest.facemesh import load_canonical_face
    from ingest.formats.wav import write_wav

    folder = root / name
    folder.mkdir(parents=True)
    n = int(seconds * fps)
    v = load_canonical_face().vertices
    image = np.stack([0.5 + v[:, 0] / 400, 0.5 - v[:, 1] / 400, -v[:, 2] / 400], axis=1)
    rng = np.random.default_rng(0)
    frames = image[None] + rng.normal(0, 1e-4, (n, 468, 3))
    np.save(folder / "landmarks.npy", frames.astype(np.float32))
    t = np.arange(int(seconds * 16000)) / 16000
    write_wav(folder / "audio_16k.wav", (0.1 * np.sin(2 * np.pi * 200 * t)).astype(np.float32),
              16000)
    (folder / "meta.json").write_text(json.dumps({"fps": fps, "speaker": "x"}))
    return folder


def test_landmark_clip_reads_its_side_files(tmp_path):
    folder = _landmark_folder(tmp_path / "corpus")
    (folder / "transcript.txt").write_text("open window\n")
    clip = load(discover([folder])[0])
    assert clip.text == "open window" and clip.words is None and clip.phones is None
    # labels and a word alignment beside the folder are read too
    (folder / "transcript.txt").unlink()
    (tmp_path / "corpus" / "clip.phones.csv").write_text(
        "start,end,phone\n0.0,0.5,SIL\n0.5,1.0,OW\n1.0,2.0,SIL\n")
    _word_textgrid(tmp_path / "corpus" / "clip.TextGrid")
    source = discover([folder])[0]
    assert source.file("labels").name == "clip.phones.csv"
    clip = load(source)
    assert [p.phone for p in clip.phones] == ["SIL", "OW", "SIL"]
    (tmp_path / "corpus" / "clip.phones.csv").unlink()
    clip = load(discover([folder])[0])
    assert clip.text == "open window" and [w.word for w in clip.words] == [None, "open",
                                                                           "window"]


def test_words_of_another_utterance_are_rejected(tmp_path):
    folder = _landmark_folder(tmp_path / "corpus")
    (folder / "transcript.txt").write_text("bin blue at f two now")
    (folder / "clip.align").write_bytes(b"0 12500 sil\r\n12500 25000 lay\r\n"
                                        b"25000 50000 sil\r\n")
    with pytest.raises(DataError, match="not the transcript's"):
        load(discover([folder])[0])
    (folder / "clip.align").write_bytes(b"0 12500 sil\r\n12500 99000 bin\r\n")
    (folder / "transcript.txt").write_text("bin")
    with pytest.raises(DataError, match="after the audio"):
        load(discover([folder])[0])


@pytest.mark.skipif(not ctc.available(), reason="hama's native library is absent")
def test_a_word_alignment_is_checked_against_the_speech(tmp_path):
    """Words beside a clip are what it says only if the transcript check agrees: an
    alignment of another utterance, or one leaving most words out, falls back to
    recognition and says so, as a transcript that does not fit does."""
    from ingest.formats.wav import write_wav
    from ingest.prepare import prepare_clip

    words = ["open", "window", "bottle", "kitchen", "garden"]
    utterance = speak(" ".join(words), Voice(word_gap=30))
    folder = _landmark_folder(tmp_path / "corpus", seconds=utterance.duration)
    write_wav(folder / "audio_16k.wav", utterance.audio, utterance.sample_rate)
    align = folder.parent / "clip.align"

    def write_align(segments):
        align.write_text("".join(f"{round(w.start * 25000)} {round(w.end * 25000)} "
                                 f"{w.word or 'sil'}\n" for w in segments))
        return prepare_clip(load(discover([folder])[0]))

    given = _word_intervals(utterance, words)
    right = write_align(given)
    assert right.segmentation == "aligned-words" and "transcript_fallback" not in right.extra
    for wrong in (  # another utterance's words at these times; the last word alone
            [WordSegment(w, g.start, g.end) for w, g in zip(
                ["please", "move", "these", "boxes", "today"], given, strict=True)],
            given[-1:]):
        clip = write_align(wrong)
        assert clip.segmentation == "recognized", wrong
        assert clip.extra["transcript_fallback"].startswith("word alignment failed: ")



@pytest.mark.skipif(not ctc.available(), reason="hama's native library is absent")
def test_a_look_alike_transcript_is_said_on_the_clips_line(tmp_path):
    """A transcript of another utterance of the same grammar passes the check (it is
    aligned), and the clip's report line says it may not be this recording's."""
    from conftest import require_shared
    from test_ctc import LOOK_ALIKE

    from ingest.formats.media import read_audio
    from ingest.formats.wav import write_wav
    from ingest.per_clip import clip_note
    from ingest.prepare import prepare_clip

    name, own, other = LOOK_ALIKE
    audio, rate = read_audio(require_shared("grid", "s1", name))
    folder = _landmark_folder(tmp_path / "corpus", seconds=len(audio) / rate)
    write_wav(folder / "audio_16k.wav", audio, rate)
    for text, doubted in ((own, False), (other, True)):
        (folder / "transcript.txt").write_text(text)
        clip = prepare_clip(load(discover([folder])[0]))
        assert clip.segmentation == "aligned" and "transcript_fallback" not in clip.extra
        assert ("transcript_doubt" in clip.extra) == doubted
        assert ("fits the audio poorly" in clip_note("", clip)) == doubted


def test_synth_labels_read_a_grid_word_alignment_as_ingest_does():
    """synth --labels clip.align (GRID's word alignment, which ingest reads beside a clip)
    was "unknown phone label file type": it is read by ingest's reader, the phones
    aligned inside its words."""
    from conftest import require_shared

    from ingest.formats.media import read_audio
    from ingest.formats.words import read_grid_align
    from ingest.readers.common import read_labels_for

    align = require_shared("grid", "s1", "bbaf2n.align")
    audio, rate = read_audio(align.with_suffix(".mp4"))
    phones = read_labels_for(align, audio, rate)
    words = [w for w in read_grid_align(align) if w.word]
    spoken = [p for p in phones if p.phone != "SIL"]
    assert len(spoken) >= 2 * len(words)  # each word at least ... two phones here
    for word in words:  # every word's phones inside its times
        inside = [p for p in spoken if word.start - 1e-6 <= p.start < word.end - 1e-6]
        assert inside and all(p.end <= word.end + 1e-6 for p in inside), word
    with pytest.raises(DataError, match="words end at"):
        read_labels_for(align, audio[: rate], rate)  # an alignment of longer speech


@pytest.mark.skipif(not ctc.available(), reason="hama's native library is absent")
def test_ingest_keeps_hama_s_posteriors_of_the_clips_whose_word_alignment_it_checked(
        tmp_path):
    """Checking a word alignment's transcript, hama hears the clip: ingest keeps what it
    heard (the clips table's posteriors), so ppg-ridge's fit does not hear it again
    (GRID's 800 word-aligned clips were all heard twice). Given phone labels, hama hears
    nothing and nothing is kept; a prepared clip resumed from the cache keeps them too."""
    from animegraph.apps.cli import main
    from db.store import Database
    from ingest import prepared_cache
    from ingest.formats.wav import write_wav
    from ingest.prepare import prepare_clip
    from ingest.tables import prepared_from_database

    words = ["open", "window", "bottle", "kitchen", "garden"]
    utterance = speak(" ".join(words), Voice(word_gap=30))
    corpus = tmp_path / "corpus"
    for name in ("aligned", "labelled"):
        folder = _landmark_folder(corpus, name, seconds=utterance.duration)
        write_wav(folder / "audio_16k.wav", utterance.audio, utterance.sample_rate)
    (corpus / "aligned.align").write_text("".join(
        f"{round(w.start * 25000)} {round(w.end * 25000)} {w.word}\n"
        for w in _word_intervals(utterance, words)))
    (corpus / "labelled.phones.csv").write_text("start,end,phone\n" + "".join(
        f"{p.start},{p.end},{p.phone}\n" for p in utterance.phones))
    db = tmp_path / "db"
    assert main(["ingest", str(corpus), "--db", str(db), "--quiet", "--no-prepare"]) == 0
    clips = {c.clip_id: c for c in prepared_from_database(Database.open(db))}
    aligned = next(c for k, c in clips.items() if "aligned" in k)
    labelled = next(c for k, c in clips.items() if "labelled" in k)
    assert aligned.segmentation == "aligned-words" and labelled.segmentation != "aligned-words"
    n = round(utterance.duration / 0.02)  # hama's frames: 50 a second
    assert aligned.posteriors.shape[1] == 39 and abs(len(aligned.posteriors) - n) <= 2
    assert aligned.posterior_blank.shape == (len(aligned.posteriors),)
    assert np.allclose(aligned.posteriors.sum(axis=1), 1, atol=0.02)  # phone posteriors
    assert labelled.posteriors is None
    clip = prepare_clip(load(discover([corpus / "aligned"])[0]))
    assert np.allclose(aligned.posteriors, clip.posteriors, atol=0.01)  # this clip's
    prepared_cache.save("k" * 64, clip, {})
    again, _ = prepared_cache.load("k" * 64)
    assert np.array_equal(again.posteriors, clip.posteriors) and clip.posteriors is not None
    assert np.array_equal(again.posterior_blank, clip.posterior_blank)
    prepared_cache.remove(["k" * 64])
