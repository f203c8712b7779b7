"""Phones heard once (:mod:`ingest.speech.heard`): a recording's segmentation is kept in
the cache folder and read back instead of running the phone engines again."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from ingest.cache import CACHE_ENV
from ingest.speech import ctc, heard
from ingest.speech.espeak import Voice, speak


@pytest.fixture()
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    return tmp_path


@pytest.fixture(scope="module")
def speech():
    utt = speak("The boat sailed across the quiet bay.", Voice())
    return utt.audio.astype(np.float32), utt.sample_rate


def _entries(cache):
    return sorted((cache / "heard").glob("*.json"))


def test_the_second_segmentation_runs_no_engine_and_gives_the_same_phones(cache, speech):
    audio, rate = speech
    with heard.remembered() as uses:
        first = heard.segment_once(audio, rate)
    assert (uses.hits, uses.misses) == (0, 1) and first[2] is False
    assert len(_entries(cache)) == 1
    kept = sorted((cache / "phones").glob("*.npy"))  # hama's outputs kept too
    ctc.forget()  # nothing remembered in this process: only the disk can answer
    with heard.remembered() as uses:
        second = heard.segment_once(audio, rate)
        ctc.posteriors(audio, rate)  # the quality checks' posteriors: read from the disk
    assert (uses.hits, uses.misses) == (1, 0) and second[2] is True
    assert second[:2] == first[:2]
    assert sorted((cache / "phones").glob("*.npy")) == kept and kept


def test_other_options_are_other_entries(cache, speech):
    audio, rate = speech
    with heard.remembered() as uses:
        recognized = heard.segment_once(audio, rate)
        aligned = heard.segment_once(audio, rate, text="The boat sailed across the quiet bay.")
        heard.segment_once(audio, rate, engine="pocketsphinx")
    assert uses.misses == 3 and len(_entries(cache)) == 3
    assert recognized[1] == "recognized" and aligned[1] == "aligned"


def test_outside_the_block_nothing_is_kept(cache, speech):
    audio, rate = speech
    segments, method, cached = heard.segment_once(audio, rate)
    assert not cached and not (cache / "heard").exists()


@pytest.mark.parametrize("damage", [
    b"not json",
    b'{"format": 1, "method": "recognized", "fallback": [], "doubts": [], '
    b'"segments": [["SIL", 0.0, 0.5]]}',  # does not reach the end of the audio
    b'{"format": 1, "method": "recognized", "fallback": [], "doubts": [], '
    b'"segments": [["../x", 0.0, 99.0]]}',
    b'{"format": 1, "method": "labels", "fallback": [], "doubts": [], "segments": []}',
])
def test_a_damaged_entry_is_ignored_and_written_again(cache, speech, damage, caplog):
    audio, rate = speech
    with heard.remembered():
        first = heard.segment_once(audio, rate)
    entry, = _entries(cache)
    entry.write_bytes(damage)
    with heard.remembered() as uses:
        again = heard.segment_once(audio, rate)
    assert (uses.hits, uses.misses) == (0, 1)
    assert again[:2] == first[:2]
    assert "not a segmentation of this audio" in caplog.text
    assert json.loads(entry.read_bytes())["segments"][0][0] == first[0][0].phone
    with heard.remembered() as uses:
        heard.segment_once(audio, rate)
    assert uses.hits == 1


def test_the_fallback_line_is_said_again_from_the_cache(cache, speech):
    audio, rate = speech
    said = []
    with heard.remembered():
        heard.segment_once(audio, rate, text="Purple elephants juggle seven violins tonight.",
                           on_fallback=said.append)
    with heard.remembered() as uses:
        again = []
        out = heard.segment_once(audio, rate, text="Purple elephants juggle seven violins "
                                 "tonight.", on_fallback=again.append)
    assert said and "fell back to phone recognition" in said[0]
    assert uses.hits == 1 and out[1] == "recognized" and again == said


def test_the_folder_is_bounded_oldest_first(tmp_path):
    for k in range(10):
        path = tmp_path / f"{k}.json"
        path.write_bytes(b"x" * 100)
        os.utime(path, ns=(k * 10**9, k * 10**9))
    (tmp_path / "sub").mkdir()
    assert heard.bound_folder(tmp_path, 450) == 6
    assert sorted(p.name for p in tmp_path.iterdir()) == ["6.json", "7.json", "8.json",
                                                          "9.json", "sub"]
    assert heard.bound_folder(tmp_path, 450) == 0
    assert heard.bound_folder(tmp_path / "missing", 0) == 0


def test_remembered_bounds_the_folders(cache, speech, monkeypatch):
    audio, rate = speech
    (cache / "heard").mkdir()
    for k in range(5):
        (cache / "heard" / f"old{k}.json").write_bytes(b"x" * 1000)
        os.utime(cache / "heard" / f"old{k}.json", ns=(k, k))
    monkeypatch.setattr(heard, "MAX_BYTES", 3000)
    with heard.remembered():
        heard.segment_once(audio, rate)
    sizes = [p.stat().st_size for p in (cache / "heard").iterdir()]
    assert sum(sizes) <= 3000
    assert len(_entries(cache)) >= 1 and not (cache / "heard" / "old0.json").exists()


def test_a_second_synth_of_a_recording_hears_no_phones_and_gives_the_same_motion(
        tiny_db, speech, cache, tmp_path, capsys):
    from animegraph.apps.cli import main
    from ingest.formats.wav import write_wav

    audio, rate = speech
    wav = tmp_path / "speech.wav"
    write_wav(wav, audio, rate)
    base = ["synth", str(wav), "--db", str(tiny_db[0]), "--guide", "none"]
    assert main([*base, "-o", str(tmp_path / "a.npz")]) == 0
    first = capsys.readouterr().err
    assert "phones heard before" not in first and "(recognized)" in first
    ctc.forget()
    assert main([*base, "--k-best", "3", "-o", str(tmp_path / "k3.npz")]) == 0
    assert "phones heard before" in capsys.readouterr().err
    assert main([*base, "-o", str(tmp_path / "b.npz")]) == 0
    assert "phones heard before" in capsys.readouterr().err
    with np.load(tmp_path / "a.npz") as a, np.load(tmp_path / "b.npz") as b:
        assert sorted(a.files) == sorted(b.files)
        for name in a.files:
            np.testing.assert_array_equal(a[name], b[name])


def test_a_doubted_transcript_is_doubted_again_from_the_cache(cache):
    """A transcript aligned with doubt (a look-alike, tests/test_ctc.py) is said again
    when its segmentation comes from the cache, to whoever collects the doubts."""
    from conftest import require_shared

    from ingest.formats.media import read_audio

    audio, rate = read_audio(require_shared("grid", "s1", "lbbk5s.mp4"))
    other = "lay blue by y four please"
    said = []
    for _ in range(2):
        with heard.remembered() as uses, ctc.doubts() as doubted:
            segments, method, cached = heard.segment_once(audio, rate, text=other)
        said.append((method, cached, list(doubted), segments))
    assert uses.hits == 1 and [s[1] for s in said] == [False, True]
    assert said[0][0] == said[1][0] == "aligned" and said[0][3] == said[1][3]
    assert len(said[0][2]) == 1 and "fits the audio poorly" in said[0][2][0]
    assert said[1][2] == said[0][2]
