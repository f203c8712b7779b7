"""Bad input speech: clipping, telephone band, music or noise are warned, never a traceback."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import require_shared
from scipy.signal import resample_poly

from animegraph.apps.cli import main
from ingest.formats.wav import write_wav
from ingest.speech import ctc
from ingest.speech.espeak import Voice, speak
from ingest.speech.quality import (
    HIGH_BAND,
    MIN_PHONE_RATE,
    MUSIC_LOW_ENERGY,
    MUSIC_PULSE,
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


def _band(sr, seconds=6.0, *, drums=True, chords=True, bpm=120.0, seed=0):
    """A music-like signal: a drum kit on eighth notes (kick, snare, hi-hat) and/or
    sustained three-note chords with harmonics changing every 2 s."""
    rng = np.random.default_rng(seed)
    n = int(seconds * sr)
    x = np.zeros(n)
    step = 60 / bpm / 2
    for i in range(int(seconds / step) if drums else 0):
        at = int(i * step * sr)
        k = np.arange(min(int(0.25 * sr), n - at)) / sr
        if i % 4 == 0:  # kick: a falling 150 -> 50 Hz thump
            x[at:at + k.size] += 0.9 * np.sin(2 * np.pi * (50 + 100 * np.exp(-k / 0.03)) * k) \
                * np.exp(-k / 0.08)
        if i % 4 == 2:  # snare: a noise burst
            x[at:at + k.size] += 0.5 * rng.standard_normal(k.size) * np.exp(-k / 0.05)
        x[at:at + k.size] += 0.15 * np.diff(rng.standard_normal(k.size + 1)) * np.exp(-k / 0.015)
    t = np.arange(n) / sr
    for j in range(int(np.ceil(seconds / 2)) if chords else 0):
        lo, hi = j * 2 * sr, min(n, (j + 1) * 2 * sr)
        root = (220.0, 174.6, 261.6, 196.0)[j % 4]
        for f in (root, root * 1.26, root * 1.5):  # a major triad
            for h in (1, 2, 3):
                x[lo:hi] += 0.08 / h * np.sin(2 * np.pi * f * h * t[lo:hi])
    return (0.8 * x / np.abs(x).max()).astype(np.float32)


@pytest.mark.parametrize("kind", ["drums and chords", "drums", "chords"])
def test_music_is_warned_from_the_sound_alone(kind):
    """Music with a beat gave the phone engine 5 confident phones per second, above
    MIN_PHONE_RATE: without a check of its own it was animated without a word."""
    sr = 16000
    band = _band(sr, drums="drums" in kind, chords="chords" in kind)
    said = _warned(band, sr)
    assert "sounds like music" in said and "lip-sync will be poor" in said, said
    q = assess(band, sr)
    if kind == "chords":  # sustained: the level never dips as speech's does
        assert q.low_energy < MUSIC_LOW_ENERGY
    else:  # a steady beat
        assert q.pulse > MUSIC_PULSE


def test_speech_is_not_called_music(speech):
    audio, sr = speech
    q = assess(audio, sr)
    assert q.low_energy > MUSIC_LOW_ENERGY and q.pulse < MUSIC_PULSE
    assert "music" not in _warned(audio, sr)
    for voice in (Voice(name="en-us+m3"), Voice(rate=120), Voice(rate=300)):
        utt = speak("Bob paid the big puppy a bit of apple pie. Maybe the boy bought a pipe.",
                    voice)
        assert "music" not in _warned(utt.audio.astype(np.float32), utt.sample_rate)
    short = assess(_band(sr, 1.5), sr)  # too short to judge either way
    assert short.low_energy is None and short.pulse is None


def test_real_speech_is_not_called_music():
    """Real speech from three corpora, calm and angry, English, German and Mandarin."""
    from ingest.formats.media import read_audio

    grid = sorted(require_shared("grid", "s1").glob("*.mp4"))[::80]
    angry = sorted(require_shared("emodb", "wav").glob("*W*.wav"))[::6]
    other = [require_shared("facegood", "wav", "1114_2_01.wav"),
             *sorted(require_shared("talkingface").glob("*/audio_16k.wav"))[::3]]
    for path in grid + angry + other:
        audio, sr = read_audio(path, 16000) if path.suffix == ".mp4" else read_audio(path)
        for start in range(0, max(1, audio.size - 10 * sr), 20 * sr):  # 10 s cuts
            said = _warned(audio[start:start + 10 * sr], sr)
            assert "music" not in said, (path.name, start, said)


def _song(speech):
    """The band with a voice over it, 10 dB under the band's peak: the phone engine
    hears enough phones in it (as in real music with drums) that the phone rate says
    nothing."""
    audio, sr = speech
    song = _band(sr)
    song[sr: sr + audio.size] += 0.3 * audio / np.abs(audio).max()
    return (0.9 * song / np.abs(song).max()).astype(np.float32), sr


@needs_hama
def test_music_the_phone_rate_misses(speech):
    song, sr = _song(speech)
    q = assess(song, sr, ctc.posteriors(song, sr))
    assert q.phone_rate > MIN_PHONE_RATE  # the old check's silence
    said = warnings_for(q)
    assert len(said) == 1 and "sounds like music" in said[0]


@needs_hama
def test_synth_animates_music_and_says_so(tiny_db, speech, tmp_path, capsys):
    song, sr = _song(speech)
    wav = tmp_path / "song.wav"
    write_wav(wav, song, sr)
    out = tmp_path / "out.csv"
    code = main(["synth", str(wav), "--db", str(tiny_db[0]), "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 0 and out.exists(), err
    assert "animegraph: warning: the audio sounds like music" in err
    assert "Traceback" not in err
