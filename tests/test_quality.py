"""Bad input speech: clipping, telephone band, music or noise are warned, never a traceback."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import resample_poly

from animegraph.apps.cli import main
from ingest.formats.wav import write_wav
from ingest.speech import ctc
from ingest.speech.espeak import speak
from ingest.speech.quality import (
    HIGH_BAND,
    NARROW_BAND_DB,
    SPEECH_BAND,
    assess,
    warnings_for,
)

needs_hama = pytest.mark.skipif(not ctc.available(), reason="the hama phone engine is not "
                                "installed (pip install hama)")


@pytest.fixture(scope="module")
def speech():
    utt = speak("The quick brown fox jumps over the lazy dog near the river bank.")
    return utt.audio.astype(np.float32), utt.sample_rate


def _warned(audio, sample_rate, with_phones=False):
    probs = ctc.posteriors(audio, sample_rate) if with_phones else None
    return " | ".join(warnings_for(assess(audio, sample_rate, probs)))


def test_clean_speech_has_no_warning(speech):
    audio, sr = speech
    assert _warned(audio, sr) == ""
    assert _warned(0.9 * audio / np.abs(audio).max(), sr) == ""  # loud is not clipped


def test_clipping(speech):
    audio, sr = speech
    clipped = np.clip(4.0 * audio / np.abs(audio).max(), -1.0, 1.0)
    assert "clipped" in _warned(clipped, sr)


def test_telephone_band(speech):
    audio, sr = speech
    narrow = resample_poly(audio, 1, 2).astype(np.float32)  # 8 kHz
    assert "8000 Hz" in _warned(narrow, 8000)
    back = resample_poly(narrow, 2, 1).astype(np.float32)  # 8 kHz brought back to 16 kHz
    assert "nothing above 4 kHz" in _warned(back, sr)


def test_narrow_band_is_said_only_when_phones_are_heard_in_the_audio(speech):
    """Phones given as labels (a batch line spoken by eSpeak NG, whose own speech has
    little above 4 kHz: "Bin blue at F two now." measures -20.2 dB) need nothing from
    the upper band: no telephone-band line then, clipping still said."""
    from animegraph.synthesis.pipeline import input_warnings

    audio, sr = speech
    back = resample_poly(resample_poly(audio, 1, 2), 2, 1).astype(np.float32)
    assert any("nothing above 4 kHz" in w for w in input_warnings(back, sr, False))
    assert input_warnings(back, sr, False, phones_heard=False) == []
    clipped = np.clip(4.0 * back / np.abs(back).max(), -1.0, 1.0)
    assert [w[:20] for w in input_warnings(clipped, sr, False, phones_heard=False)] == [
        "the audio is clipped"]


def test_short_speech_is_not_called_narrow_band(speech):
    """A fifth of a second of speech is a syllable or less: a vowel has little above
    4 kHz, telephone band or not, so the band is not judged on it."""
    audio, sr = speech
    n = int(0.2 * sr)
    pieces = [audio[i:i + n] for i in range(0, len(audio) - n, n // 4)]

    def band_db(x):  # an oracle of the measure: high band's density against speech band's
        power = np.abs(np.fft.rfft(x.astype(np.float64))) ** 2
        f = np.fft.rfftfreq(len(x), 1 / sr)

        def density(band):
            return power[(f > band[0]) & (f <= band[1])].mean()

        return 10 * np.log10(density(HIGH_BAND) / density(SPEECH_BAND))

    vowel = min((p for p in pieces if np.abs(p).max() > 0.1), key=band_db)
    assert band_db(vowel) < NARROW_BAND_DB  # what the whole-band test would call narrow
    assert _warned(vowel, sr) == ""
    assert assess(vowel, sr).high_band_db is None
    # a second of sound is judged: the telephone band brought back to 16 kHz still is
    back = resample_poly(resample_poly(audio, 1, 2), 2, 1).astype(np.float32)
    assert "nothing above 4 kHz" in _warned(back[: int(1.5 * sr)], sr)


def test_speech_with_little_treble_is_not_telephone_band(speech):
    """Speech whose upper band falls steeply (a dull microphone, a lossy codec: 11 % of
    GRID's clips) still has more above 4 kHz than a resampler leaks: not narrow-band.
    The share of all energy above 4 kHz, tested before, called it telephone band."""
    from scipy.signal import butter, sosfilt

    audio, sr = speech
    dull = sosfilt(butter(1, 1500, fs=sr, output="sos"), audio).astype(np.float32)
    power = np.abs(np.fft.rfft(dull.astype(np.float64))) ** 2
    assert power[np.fft.rfftfreq(len(dull), 1 / sr) > 4000].sum() / power.sum() < 0.0005
    assert _warned(dull, sr) == ""
    assert NARROW_BAND_DB < assess(dull, sr).high_band_db


@needs_hama
def test_speech_the_engine_knows_and_noise_it_does_not(speech, rng):
    audio, sr = speech
    assert "little speech" not in _warned(audio, sr, with_phones=True)
    t = np.arange(3 * sr) / sr
    chords = sum(np.sin(2 * np.pi * f * t) for f in (220.0, 277.2, 329.6, 440.0))
    music = (0.2 * chords * (1 + 0.5 * np.sin(2 * np.pi * 2 * t))).astype(np.float32)
    noise = (0.1 * rng.standard_normal(3 * sr)).astype(np.float32)
    for sound in (music, noise):
        assert "little speech" in _warned(sound, sr, with_phones=True)


def test_synth_says_what_is_wrong_and_still_animates(tiny_db, speech, tmp_path, capsys):
    audio, sr = speech
    wav = tmp_path / "clipped.wav"
    write_wav(wav, np.clip(4.0 * audio / np.abs(audio).max(), -1.0, 1.0), sr)
    out = tmp_path / "out.csv"
    code = main(["synth", str(wav), "--db", str(tiny_db[0]), "-o", str(out), "--explain"])
    captured = capsys.readouterr()
    assert code == 0 and out.exists()
    assert "animegraph: warning: the audio is clipped" in captured.err
    assert "warning: the audio is clipped" in captured.out  # --explain says it too
    assert "Traceback" not in captured.err


@pytest.mark.parametrize("kind", ["silence", pytest.param("music", marks=needs_hama)])
def test_no_speech_with_a_transcript_is_one_error(tiny_db, tmp_path, capsys, kind):
    """A transcript cannot match audio that holds no speech: the error says so alone,
    without a warning first that the transcript does not match."""
    sr = 16000
    t = np.arange(3 * sr) / sr
    if kind == "silence":
        audio = np.zeros(3 * sr, np.float32)
    else:  # chords, as the prober's music.wav: no phone in them
        chords = sum(np.sin(2 * np.pi * f * h * t) / h
                     for f in (261.6, 329.6, 392.0) for h in (1, 2, 3))
        audio = (0.2 * chords / np.abs(chords).max()).astype(np.float32)
    wav = tmp_path / f"{kind}.wav"
    write_wav(wav, audio, sr)
    code = main(["synth", str(wav), "--db", str(tiny_db[0]), "--text",
                 "bin blue at f two now", "--guide", "none", "-o", str(tmp_path / "out.csv")])
    err = capsys.readouterr().err
    said = [ln for ln in err.splitlines() if "warning" in ln or "error" in ln]
    assert code == 1 and len(said) == 1, err
    assert ("the audio is silent" if kind == "silence" else "no speech found") in said[0]
