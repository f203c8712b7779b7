"""Tests of the CTC phone engine (ingest.speech.ctc, the model the hama wheel ships) and
the engine choice (ingest.speech.engines). Real model, real eSpeak NG speech, no mocks."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from conftest import require_shared

from db.errors import DataError, ParameterError
from ingest.formats.phones_csv import Segment
from ingest.speech import ctc, ctc_timing
from ingest.speech.engines import ENGINES, aligner, check_engine, recognizer
from ingest.speech.espeak import Voice, speak
from ingest.speech.phones import PHONE_SET, PHONES, SILENCE
from ingest.speech.scoring import boundary_errors, phone_error_rate
from ingest.speech.segment import segment
from ingest.speech.sphinx import BOUNDARY_OFFSET, align_phones

pytestmark = pytest.mark.skipif(not ctc.available(), reason="hama's native library is absent")

SENTENCES = (
    "Please move the boxes off the porch.",
    "The young boy took a brown bag of fresh cheese to the village market.",
)
#: Measured: 0.22 on average over 80 eSpeak clips (scripts/eval_segmentation.py).
RECOGNITION_PER_LIMIT = 0.45


@pytest.fixture(scope="module")
def spoken():
    return [speak(text, Voice()) for text in SENTENCES]


def _reference(utterance) -> list[Segment]:
    return [Segment(p.phone, p.start, p.end) for p in utterance.phones]


def _check_tiling(segments, duration):
    assert segments[0].start == 0.0
    assert segments[-1].end == pytest.approx(duration)
    for prev, cur in zip(segments, segments[1:], strict=False):
        assert prev.end == cur.start
        assert not (prev.phone == SILENCE == cur.phone)
    assert all(s.phone in PHONE_SET and s.end > s.start for s in segments)


def test_ipa_map_targets_the_phone_set():
    assert set(ctc.IPA_TO_ARPABET.values()) <= PHONE_SET - {SILENCE}
    # every vowel and consonant of the project is reachable from some IPA symbol
    assert set(ctc.IPA_TO_ARPABET.values()) == PHONE_SET - {SILENCE}


def test_posteriors(spoken):
    u = spoken[0]
    post = ctc.posteriors(u.audio, u.sample_rate)
    duration = len(u.audio) / u.sample_rate
    assert post.shape[1] == len(PHONES)
    assert abs(len(post) - duration * ctc.FRAME_RATE) <= 2
    assert np.all(post >= 0)
    np.testing.assert_allclose(post.sum(axis=1), 1.0, atol=1e-4)
    # speech frames: some phone other than SIL is most likely somewhere
    assert np.sum(np.argmax(post, axis=1) != PHONES.index(SILENCE)) >= 10


def test_ingest_keeps_the_models_outputs_on_disk(spoken, tmp_path, monkeypatch, caplog):
    """Within kept_on_disk the posteriors are written to the cache and read back, with
    identical results and no model run; a damaged file is ignored and replaced; outside
    it nothing is written."""
    monkeypatch.setenv("ANIMEGRAPH_CACHE", str(tmp_path))
    u = spoken[0]
    ctc.forget()
    fresh = ctc.recognize(u.audio, u.sample_rate), ctc.posteriors(u.audio, u.sample_rate)
    assert not (tmp_path / "phones").exists()  # synthesis keeps nothing
    ctc.forget()
    with ctc.kept_on_disk():
        ctc.posteriors(u.audio, u.sample_rate)
    (kept,) = (tmp_path / "phones").iterdir()
    # the piece layout is in the name: posteriors heard in other pieces are not read
    assert kept.name.endswith(f"-pieces{ctc.PIECE_LAYOUT}.npy")
    ctc.forget()

    def no_model(samples):
        raise AssertionError("the model ran")

    with monkeypatch.context() as m, ctc.kept_on_disk():
        m.setattr(ctc, "_log_probs", no_model)
        again = ctc.recognize(u.audio, u.sample_rate), ctc.posteriors(u.audio, u.sample_rate)
    assert again[0] == fresh[0]
    np.testing.assert_array_equal(again[1], fresh[1])
    for damage in (b"not numpy", None, b"x" * (len(fresh[1]) * len(PHONES) * 8 + 8192)):
        if damage is None:  # a well-formed file of the wrong shape
            np.save(kept, np.ones((3, 2)), allow_pickle=False)
        else:  # garbage, or more bytes than this audio's posteriors can take
            kept.write_bytes(damage)
        ctc.forget()
        caplog.clear()
        with ctc.kept_on_disk(), caplog.at_level(logging.WARNING, logger="ingest.speech.ctc"):
            np.testing.assert_array_equal(ctc.posteriors(u.audio, u.sample_rate), fresh[1])
        assert np.load(kept, allow_pickle=False).shape == (len(fresh[1]), len(PHONES))
        if damage is not None and len(damage) > 100:  # refused unread, by its size
            assert "bytes, more than this audio's" in caplog.text
    # what an older hama or piece layout kept of this audio goes when the model runs
    # again (it would never be read); another audio's posteriors stay
    stale = kept.with_name(f"{kept.name.split('-')[0]}-hama0.1-pieces1.npy")
    other = kept.with_name("0123abcd-hama0.1-pieces1.npy")
    kept.rename(stale)
    other.write_bytes(b"another audio's")
    ctc.forget()
    with ctc.kept_on_disk():
        ctc.posteriors(u.audio, u.sample_rate)
    assert sorted((tmp_path / "phones").iterdir()) == sorted([kept, other])
    ctc.forget()


def test_kept_outputs_of_other_rates_are_found_without_resampling(spoken, tmp_path):
    """A recording at 44.1 kHz heard before: its posteriors come from the cache in a new
    process without importing scipy.signal (the resampler), equal to the first ones; a
    damaged digest file is ignored and written again."""
    import subprocess
    import sys

    from scipy.signal import resample_poly

    from ingest.formats.wav import write_wav

    u = spoken[0]
    wav = tmp_path / "speech.wav"
    write_wav(wav, resample_poly(u.audio, 441, 160).astype(np.float32), 44100)
    code = (
        "import sys\n"
        "import numpy as np\n"
        "from ingest.formats.media import read_audio\n"
        "from ingest.speech import ctc\n"
        f"audio, rate = read_audio({str(wav)!r})\n"
        "with ctc.kept_on_disk():\n"
        "    probs = ctc.posteriors(audio, rate)\n"
        f"np.save({str(tmp_path)!r} + '/' + sys.argv[1], probs)\n"
        "print('scipy.signal' in sys.modules)\n")
    env = {**__import__("os").environ, "ANIMEGRAPH_CACHE": str(tmp_path / "cache")}

    def run(name: str) -> tuple[bool, np.ndarray]:
        done = subprocess.run([sys.executable, "-c", code, name], env=env, check=True,
                              capture_output=True, text=True)
        return done.stdout.split()[-1] == "True", np.load(tmp_path / f"{name}.npy")

    resampled, first = run("first")
    assert resampled  # the model heard it: resampled to 16 kHz first
    (alias,) = (tmp_path / "cache" / "phones").glob("*.at16k")
    resampled, again = run("again")
    assert not resampled
    np.testing.assert_array_equal(again, first)
    alias.write_text("not a digest of anything, not 32")
    resampled, damaged = run("damaged")
    assert resampled and len(alias.read_text()) == 32
    np.testing.assert_array_equal(damaged, first)


def test_threads_each_take_a_session_and_get_what_one_thread_gets(spoken):
    """Calls on several threads run on sessions of their own (hama's engine is
    single-threaded), never more than the model allows, with the serial results."""
    from concurrent.futures import ThreadPoolExecutor

    audio = [(u.audio, u.sample_rate) for u in spoken] * 3
    ctc.forget()
    serial = [ctc.posteriors(a, r) for a, r in audio[:2]]
    model = ctc._model()
    with ThreadPoolExecutor(4) as pool:
        ctc.forget()
        threaded = list(pool.map(lambda ar: ctc.posteriors(*ar), audio))
    for k, post in enumerate(threaded):
        np.testing.assert_array_equal(post, serial[k % 2])
    assert 1 <= model.made <= model.limit
    # every session made is idle again, and a call that finds none idle waits for one
    assert model.idle.qsize() == model.made
    held = [model.idle.get() for _ in range(model.made)]
    limit, model.limit = model.limit, model.made
    with ThreadPoolExecutor(1) as pool:
        waiting = pool.submit(lambda: ctc._log_probs(np.zeros(1600, dtype=np.float32)))
        assert not waiting.done()
        model.idle.put(held.pop())
        assert waiting.result(timeout=60).shape[0] > 0
    for session in held:
        model.idle.put(session)
    model.limit = limit



def test_audio_is_cut_at_its_quietest_near_even_places():
    """The pieces (ctc._pieces): one below SPLIT_SECONDS, two from it, one per started
    CHUNK_SECONDS beyond; each cut in the quietest 100 ms within CUT_WINDOW of its even
    place (here a 0.2 s gap off the middle; a longer one further away is out of reach)."""
    rng = np.random.default_rng(0)
    rate, frame = ctc.SAMPLE_RATE, ctc.SAMPLE_RATE // ctc.FRAME_RATE

    def noise(seconds, gaps=()):
        audio = rng.normal(0, 0.1, int(seconds * rate)).astype(np.float32)
        for start, length in gaps:
            audio[int(start * rate): int((start + length) * rate)] = 0.0
        return audio

    short = ctc.SPLIT_SECONDS - 0.5
    assert ctc._pieces(noise(short)).tolist() == [0, short * ctc.FRAME_RATE]
    seconds = ctc.SPLIT_SECONDS + 2  # even cut at seconds / 2; the 0.2 s gap within reach
    gap = seconds / 2 + 0.5
    assert 0.5 + 0.2 < ctc.CUT_WINDOW
    bounds = ctc._pieces(noise(seconds, [(1.0, 0.5), (gap, 0.2)]))
    # the quietest 100 ms (5 frames) lie wholly in the gap: its frames 2-7 of 10; the
    # first of those is the nearest to the even place
    assert bounds.tolist() == [0, round(gap * ctc.FRAME_RATE) + 2, seconds * ctc.FRAME_RATE]
    # beyond CHUNK_SECONDS: a piece per started CHUNK_SECONDS, cuts near even places
    seconds = 2 * ctc.CHUNK_SECONDS + 5
    bounds = ctc._pieces(noise(seconds))
    assert len(bounds) == 4 and bounds[-1] == seconds * ctc.FRAME_RATE
    even = np.arange(4) * seconds * ctc.FRAME_RATE / 3
    assert np.abs(bounds - even).max() <= ctc.CUT_WINDOW * ctc.FRAME_RATE
    assert np.diff(bounds).max() * frame <= (ctc.CHUNK_SECONDS + 2 * ctc.CUT_WINDOW) * rate


def test_audio_is_heard_in_pieces_on_every_core_as_on_one(spoken, monkeypatch):
    """A recording of SPLIT_SECONDS or more is heard in pieces, on threads of their own,
    with the one-thread result bit for bit (the pieces depend on the audio alone)."""
    gap = np.zeros(spoken[0].sample_rate // 4, dtype=np.float32)
    audio = np.concatenate([spoken[1].audio, gap, spoken[0].audio, gap, spoken[1].audio])
    rate = spoken[0].sample_rate
    assert ctc.SPLIT_SECONDS <= len(audio) / rate < ctc.CHUNK_SECONDS
    results, threads = [], []
    real_pool = __import__("concurrent.futures").futures.ThreadPoolExecutor

    def counting_pool(n, **kwargs):
        threads.append(n)
        return real_pool(n, **kwargs)

    monkeypatch.setattr("concurrent.futures.ThreadPoolExecutor", counting_pool)
    for budget in (1, 2):
        monkeypatch.setattr(ctc, "thread_budget", lambda budget=budget: budget)
        ctc.forget()
        results.append(ctc.posteriors(audio, rate))
    ctc.forget()
    np.testing.assert_array_equal(results[0], results[1])
    assert len(results[0]) == ctc._pieces(ctc._resample(audio, rate))[-1]
    assert threads == ([2] if ctc._model().limit >= 2 else [])


def test_recognize_is_roughly_right(spoken):
    for u in spoken:
        segments = ctc.recognize(u.audio, u.sample_rate)
        _check_tiling(segments, len(u.audio) / u.sample_rate)
        assert phone_error_rate(_reference(u), segments) < RECOGNITION_PER_LIMIT


def test_align_recovers_timing(spoken):
    errors = []
    for u in spoken:
        segments = ctc.align(u.audio, u.sample_rate, u.text)
        _check_tiling(segments, len(u.audio) / u.sample_rate)
        assert phone_error_rate(_reference(u), segments) < 0.2  # CMUdict vs eSpeak phones
        errors.append(boundary_errors(_reference(u), segments))
    errors = np.concatenate(errors)
    assert errors.size >= 40
    assert np.median(errors) < 0.02


@pytest.mark.parametrize("rate", [8000, 44100])
def test_other_sample_rates(spoken, rate):
    from scipy.signal import resample_poly

    u = spoken[0]
    audio = resample_poly(u.audio, rate, u.sample_rate)
    segments = ctc.align(audio, rate, u.text)
    _check_tiling(segments, len(audio) / rate)
    assert phone_error_rate(_reference(u), segments) < 0.3


def test_wrong_transcript_is_a_data_error(spoken):
    u = spoken[0]
    with pytest.raises(DataError, match="does not match"):
        ctc.align(u.audio, u.sample_rate, SENTENCES[1])


def test_a_transcript_that_leaves_words_out_does_not_match():
    """CTC's blank absorbs untranscribed speech cheaply: a one-word transcript of a GRID
    sentence fits within MAX_ALIGN_LOSS, and only the share of phones it names shows
    that it is not what the audio says."""
    from ingest.formats.media import read_audio

    audio, rate = read_audio(require_shared("grid", "s1", "bbaf2n.mp4"))
    ctc.check_transcript(audio, rate, "bin blue at f two now")  # what is said
    for partial in ("now", "zebra"):
        assert ctc.transcript_loss(audio, rate, partial) < ctc.MAX_ALIGN_LOSS
        with pytest.raises(DataError, match="words missing"):
            ctc.check_transcript(audio, rate, partial)
    assert segment(audio, rate, text="now", on_fallback=lambda line: None)[1] == "recognized"


def test_the_default_aligner_rejects_a_transcript_of_another_utterance(spoken, caplog):
    # PocketSphinx aligns: it finds a path through any transcript, so hama checks first.
    u = spoken[0]
    ctc.check_transcript(u.audio, u.sample_rate, u.text)  # the right one passes
    assert segment(u.audio, u.sample_rate, text=u.text)[1] == "aligned"
    with pytest.raises(DataError, match="does not match"):
        ctc.check_transcript(u.audio, u.sample_rate, SENTENCES[1])
    with pytest.raises(DataError, match="does not match"):
        aligner("auto")(u.audio, u.sample_rate, SENTENCES[1])
    with caplog.at_level(logging.WARNING, logger="ingest.speech.segment"):
        segments, method = segment(u.audio, u.sample_rate, text=SENTENCES[1])
    assert method == "recognized" and "fell back" in caplog.text
    assert segments == recognizer("auto")(u.audio, u.sample_rate)
    # A shorter transcript PocketSphinx alone forces onto the speech without complaint
    fox = speak("The quick brown fox jumps over the lazy dog near the river bank.", Voice())
    wrong = "Bin blue at F two now please."
    assert segment(fox.audio, fox.sample_rate, text=wrong, engine="pocketsphinx")[1] == \
        "aligned"
    assert segment(fox.audio, fox.sample_rate, text=wrong)[1] == "recognized"



#: A GRID clip and a sentence of the same grammar with three words changed: within
#: MAX_ALIGN_LOSS, beyond DOUBT_ALIGN_LOSS (0.02 and 0.47 nats/frame when measured).
LOOK_ALIKE = ("lbbk5s.mp4", "lay blue by k five soon", "lay blue by y four please")


def test_a_look_alike_transcript_is_aligned_with_a_warning(caplog):
    """Such a transcript passes the check, so it is aligned; but it is said, once, to
    whoever collects the doubts (synth's warnings, a clip's report line), else logged."""
    from ingest.formats.media import read_audio

    name, own, other = LOOK_ALIKE
    audio, rate = read_audio(require_shared("grid", "s1", name))
    assert (ctc.transcript_loss(audio, rate, own) < ctc.DOUBT_ALIGN_LOSS
            < ctc.transcript_loss(audio, rate, other) < ctc.MAX_ALIGN_LOSS)
    with ctc.doubts() as doubted:
        ctc.check_transcript(audio, rate, own)
        assert doubted == []
        ctc.check_transcript(audio, rate, other)
        _, method = segment(audio, rate, text=other)  # checked again by the aligner
    assert method == "aligned" and len(doubted) == 1
    assert "fits the audio poorly" in doubted[0] and "this recording's" in doubted[0]
    with caplog.at_level(logging.WARNING, logger="ingest.speech.ctc"):
        ctc.check_transcript(audio, rate, other)
    assert "fits the audio poorly" in caplog.text

def test_too_long_transcript_is_a_data_error(spoken):
    u = spoken[0]
    short = u.audio[: int(0.3 * u.sample_rate)]
    with pytest.raises(DataError):
        ctc.align(short, u.sample_rate, SENTENCES[1])


def test_silence_and_short_clips():
    assert ctc.recognize(np.zeros(32000), 16000) == [Segment(SILENCE, 0.0, 2.0)]
    assert ctc.recognize(np.zeros(800), 16000) == [Segment(SILENCE, 0.0, 0.05)]
    with pytest.raises(ParameterError):
        ctc.align(np.zeros(32000), 16000, "   ")


def test_ctc_viterbi_finds_the_known_path():
    # classes: 0 blank, 1 A, 2 B; frames: A A blank B B blank A
    best = [1, 1, 0, 2, 2, 0, 1]
    log_probs = np.full((len(best), 3), np.log(0.05))
    log_probs[np.arange(len(best)), best] = np.log(0.9)
    starts, score = ctc_timing.ctc_viterbi(log_probs, np.array([1, 2, 1]), blank=0)
    assert starts.tolist() == [0, 3, 6]
    assert score == pytest.approx(7 * np.log(0.9))
    assert ctc_timing.ctc_viterbi(log_probs, np.array([1, 2, 1]), blank=0,
                                  path=False) == (None, score)
    # a repeated label needs a blank between its two copies
    starts, _ = ctc_timing.ctc_viterbi(log_probs, np.array([1, 1]), blank=0)
    assert starts[1] > starts[0] + 1
    with pytest.raises(DataError, match="frames"):
        ctc_timing.ctc_viterbi(log_probs[:2], np.array([1, 1, 2]), blank=0)


def test_engine_choice(spoken, caplog):
    u = spoken[0]
    assert check_engine(None) == "auto"
    assert set(ENGINES) == {"auto", "hama", "pocketsphinx"}
    with pytest.raises(ParameterError, match="phone engine"):
        check_engine("festival")
    with pytest.raises(ParameterError, match="phone engine"):
        segment(u.audio, u.sample_rate, engine="festival")
    assert recognizer("hama") is ctc.recognize
    assert aligner("hama") is ctc.align
    assert aligner("auto") is not ctc.align  # PocketSphinx aligns by default
    hama, method = segment(u.audio, u.sample_rate, engine="hama")
    assert method == "recognized" and hama == ctc.recognize(u.audio, u.sample_rate)
    with caplog.at_level(logging.WARNING, logger="ingest.speech.segment"):
        segments, method = segment(u.audio, u.sample_rate, text=SENTENCES[1], engine="hama")
    assert method == "recognized"
    assert "transcript alignment failed" in caplog.text and "fell back" in caplog.text


def test_trailing_silence_starts_at_the_first_pause_after_the_last_phone():
    """After the last phone, the clip is silence from its first quiet run of MIN_PAUSE
    or more, even if a louder frame (a breath) follows: no phone was heard there (GRID's
    last phones used to run on to the breath). With no pause before the breath, the
    silence starts after it."""
    hop = ctc.SAMPLE_RATE // ctc.FRAME_RATE
    rng = np.random.default_rng(0)
    level = np.full(50, 1e-4)          # 50 frames of 20 ms: quiet ...
    level[5:21] = 0.3                  # ... the phone's speech
    level[30:33] = 0.3                 # ... a breath after a 9-frame pause
    samples = (rng.standard_normal(50 * hop) * np.repeat(level, hop)).astype(np.float64)
    segs = ctc_timing.timed(["AA"], np.array([5]), np.array([10]), samples, 50, 1.0, False)
    assert [s.phone for s in segs] == [SILENCE, "AA", SILENCE]
    assert segs[-1].start == pytest.approx(21 / ctc.FRAME_RATE)
    level[21:30] = 0.3                 # no pause before the breath: the quiet end only
    samples = (rng.standard_normal(50 * hop) * np.repeat(level, hop)).astype(np.float64)
    segs = ctc_timing.timed(["AA"], np.array([5]), np.array([10]), samples, 50, 1.0, False)
    assert segs[-1].phone == SILENCE and segs[-1].start == pytest.approx(33 / ctc.FRAME_RATE)


def test_auto_recognition_names_phones_with_hama_and_places_them_with_pocketsphinx(spoken):
    auto = recognizer("auto")
    for u in spoken:
        duration = len(u.audio) / u.sample_rate
        named = ctc.recognize(u.audio, u.sample_rate)
        placed = auto(u.audio, u.sample_rate, refine=False)
        _check_tiling(placed, duration)
        assert [s.phone for s in placed if s.phone != SILENCE] == \
            [s.phone for s in named if s.phone != SILENCE]
        # PocketSphinx's timing: every interior boundary on its 10 ms frame grid
        frames = (np.array([s.start for s in placed[1:]]) - BOUNDARY_OFFSET) * 100
        np.testing.assert_allclose(frames, np.round(frames), atol=1e-3)
        onset = boundary_errors(_reference(u), auto(u.audio, u.sample_rate))
        assert np.median(np.abs(onset)) < 0.015


def test_align_phones_without_a_path_or_phones():
    u = speak(SENTENCES[0], Voice())
    assert align_phones(u.audio, u.sample_rate, [SILENCE]) is None
    assert align_phones(np.zeros(800), 16000, ["AA"]) is None  # too short to hold a phone
    with pytest.raises(ParameterError, match="phone set"):
        align_phones(u.audio, u.sample_rate, ["AA", "Q9"])
    # far more phones than 0.3 s can hold: no path, and "auto" keeps hama's own timing
    short = u.audio[: int(0.3 * u.sample_rate)]
    assert align_phones(short, u.sample_rate, ["AA", "B"] * 60) is None
