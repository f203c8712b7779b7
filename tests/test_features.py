"""Tests of ingest.speech.features: RASTA-PLP (Cao et al. 2005 §4.1), MFCC and phone slicing.

Real signals throughout: eSpeak NG speech with its exact phone timing, impulses, noise.
The thresholds were measured on this implementation; each comment gives the measured value.
"""

from __future__ import annotations

import librosa
import numpy as np
import pytest
from scipy.signal import freqz, lfilter

from db.errors import DataError, ParameterError
from ingest.speech.espeak import speak
from ingest.speech.features import (
    RASTA_DENOMINATOR,
    RASTA_NUMERATOR,
    RastaPlpConfig,
    frame_times,
    mfcc,
    rasta_plp,
    slice_frames,
)
from ingest.speech.phones import VOWELS

PLP = RastaPlpConfig(rasta=False)

TEXTS = (
    "Please call Stella. Ask her to bring these things with her from the store.",
    "Six spoons of fresh snow peas, five thick slabs of blue cheese, "
    "and maybe a snack for her brother Bob.",
    "She sees the sheep sleeping in the green field, and the cat sits on a soft mat.",
    "We also need a small plastic snake and a big toy frog for the kids.",
)


@pytest.fixture(scope="module")
def utterances():
    return [speak(text) for text in TEXTS]


@pytest.fixture(scope="module")
def speech(utterances):
    """The first sentence at 16 kHz with a -50 dB white-noise floor, as in a real recording."""
    u = utterances[0]
    noise = np.random.default_rng(3).standard_normal(len(u.audio))
    return u.audio.astype(np.float64) + 10 ** (-50 / 20) * noise, u.sample_rate


# ---------------------------------------------------------------------------------------------
# The RASTA filter
# ---------------------------------------------------------------------------------------------


def test_rasta_filter_is_a_modulation_band_pass():
    frame_rate = 100.0  # frames per second at the default 10 ms hop

    def db(freqs):
        freqs = np.atleast_1d(np.asarray(freqs, dtype=np.float64))
        _, h = freqz(RASTA_NUMERATOR, RASTA_DENOMINATOR, worN=freqs, fs=frame_rate)
        return 20 * np.log10(np.abs(h) + 1e-300)

    # Zeros at DC (constant channel offsets) and at the frame-rate Nyquist: exactly -inf.
    assert db(0.0)[0] < -200 and db(50.0)[0] < -200  # -307 dB, -328 dB
    # Slow drifts are attenuated: -11.9 dB at 0.25 Hz, -19.6 dB at 0.1 Hz.
    assert db(0.25)[0] < -10 and db(0.1)[0] < -18
    # Syllable-rate modulations pass: -2.69 .. -0.28 dB over 1-12 Hz.
    assert db(np.linspace(1, 12, 45)).min() > -3.0
    # Fast modulations are rejected: at most -16.7 dB over 25-50 Hz.
    assert db(np.linspace(25, 50, 101)).max() < -15
    # Peak at 3.83 Hz, the syllable rate.
    f = np.linspace(0, 50, 4001)
    assert 3.0 < f[np.argmax(db(f))] < 5.0


def test_rasta_removes_a_fixed_channel_far_better_than_plp(speech):
    x, sr = speech
    skip = 50  # frames: the first 0.5 s

    def relative_change(y, config):
        a = rasta_plp(x, sr, config=config)[skip:].astype(np.float64)
        b = rasta_plp(y, sr, config=config)[skip:].astype(np.float64)
        # The change the channel causes, relative to the curve's own variation over time.
        return np.linalg.norm(b - a) / np.linalg.norm(a - a.mean(axis=0))

    # Measured (RASTA vs PLP): tilt 0.030 vs 0.275 (ratio 0.11); resonant EQ 0.072 vs 0.306
    # (0.24). With digital-silence pauses instead of a noise floor the ratios are about 0.4:
    # the -90 dB floor does not follow the channel, so its offset comes and goes at each pause.
    channels = {
        "tilt": (([1.0, -0.5], [1.0]), 0.2),  # +9.5 dB from 0 Hz to Nyquist
        "resonant EQ": (([1.0, -1.6, 0.8], [1.0, -1.2, 0.5]), 0.4),
    }
    for name, ((b, a), max_ratio) in channels.items():
        y = lfilter(b, a, x)
        with_rasta, plain = relative_change(y, RastaPlpConfig()), relative_change(y, PLP)
        assert plain > 0.2, name  # the channel does change plain PLP
        assert with_rasta < max_ratio * plain, (name, with_rasta, plain)


def test_rasta_is_gain_invariant_and_plp_c0_is_log_gain(speech):
    x, sr = speech
    ras, ras_quiet = rasta_plp(x, sr), rasta_plp(0.1 * x, sr)
    plp, plp_quiet = rasta_plp(x, sr, config=PLP), rasta_plp(0.1 * x, sr, config=PLP)
    # PLP: -20 dB of gain scales the loudness spectrum by 0.01 ** 0.33, so c0 = log(gain)
    # drops by 0.33 ln 100 = 1.5197 (median measured 1.5174; the -90 dB floor does not scale)
    # and the spectral shape c1..c8 stays (median |change| 2e-4).
    shift = plp - plp_quiet
    assert np.median(shift[:, 0]) == pytest.approx(0.33 * np.log(100), abs=0.01)
    assert np.median(np.abs(shift[:, 1:])) < 0.01
    # RASTA: a constant gain is a DC offset of every log band, removed entirely.
    assert np.median(np.abs(ras - ras_quiet)) < 0.01


def test_rasta_start_has_no_transient():
    # Ellis primes the filter with the first four frames, so a steady signal's level (a DC
    # offset of every log band) gives no start-up spike. Measured: frames 4..30 deviate at
    # most 0.096 from the steady state (frames 100..), 0.7 times the steady frames' own
    # spread (0.138); with a zero initial state they are off by 7.9.
    x = 0.3 * np.random.default_rng(4).standard_normal(2 * 16000)
    f = rasta_plp(x, 16000).astype(np.float64)
    # The priming frames are the same whatever the signal (a unit critical-band spectrum).
    np.testing.assert_array_equal(f[:4], rasta_plp(np.zeros(400), 16000)[[0, 0, 0, 0]])
    steady = f[100:]
    deviation = np.abs(f[4:30] - steady.mean(axis=0)).max()
    assert deviation < 2 * np.abs(steady - steady.mean(axis=0)).max(), deviation


def _ellis_rastaplp(frames: list[np.ndarray], sample_rate: int, rasta: bool) -> np.ndarray:
    """Line-by-line transcription of Ellis' rastaplp.m for already-cut frames (loops,
    complex FFTs, scipy's Toeplitz solver): an independent code path for the same method."""
    from scipy.linalg import solve_toeplitz

    winpts = len(frames[0])
    nfft = int(2 ** np.ceil(np.log2(winpts)))
    window = 0.5 * (1 - np.cos(2 * np.pi * np.arange(1, winpts + 1) / (winpts + 1)))
    pspec = np.array([np.abs(np.fft.fft(f * 32768 * window, nfft)[: nfft // 2 + 1]) ** 2
                      for f in frames]).T + winpts  # powspec.m, (nfreq, nframes)
    bark = lambda f: 6 * np.arcsinh(np.asarray(f) / 600)  # noqa: E731
    nfilts = int(np.ceil(bark(sample_rate / 2))) + 1
    binbarks = bark(np.arange(nfft // 2 + 1) * sample_rate / nfft)
    wts = np.zeros((nfilts, nfft // 2 + 1))
    for i in range(nfilts):  # fft2barkmx.m
        mid = i * bark(sample_rate / 2) / (nfilts - 1)
        lof, hif = binbarks - mid - 0.5, binbarks - mid + 0.5
        wts[i] = 10 ** np.minimum(0, np.minimum(hif, -2.5 * lof))
    aspec = wts @ pspec
    if rasta:  # rastafilt.m
        numer = -np.arange(-2, 3) / 10
        lg = np.log(aspec)
        _, z = lfilter(numer, 1, lg[:, :4], axis=1, zi=np.zeros((nfilts, 4)))
        rest = lfilter(numer, [1, -0.94], lg[:, 4:], axis=1, zi=z)[0]
        aspec = np.exp(np.hstack([np.zeros((nfilts, 4)), rest]))
    fsq = (600 * np.sinh(np.linspace(0, bark(sample_rate / 2), nfilts) / 6)) ** 2  # postaud.m
    eql = (fsq / (fsq + 1.6e5)) ** 2 * (fsq + 1.44e6) / (fsq + 9.61e6)
    post = (eql[:, None] * aspec) ** 0.33
    post = post[[1, *range(1, nfilts - 1), nfilts - 2]]
    r = np.real(np.fft.ifft(np.vstack([post, post[nfilts - 2 : 0 : -1]]), axis=0))  # dolpc.m
    cep = np.zeros((9, post.shape[1]))
    for j in range(post.shape[1]):
        a = np.r_[1, solve_toeplitz(r[:8, j], -r[1:9, j])]
        cep[0, j] = np.log(r[0, j] + a[1:] @ r[1:9, j])  # lpc2cep.m
        for n in range(1, 9):
            cep[n, j] = -(a[n] + sum((n - m) * a[m] * cep[n - m, j] for m in range(1, n)) / n)
    return (cep * np.r_[1, np.arange(1, 9) ** 0.6][:, None]).T  # lifter.m


@pytest.mark.parametrize("sample_rate", [16000, 44100])
@pytest.mark.parametrize("rasta", [True, False])
def test_matches_a_transcription_of_ellis_rastaplp(sample_rate, rasta):
    u = speak(TEXTS[3], sample_rate=sample_rate)
    x = u.audio.astype(np.float64)
    ours = rasta_plp(x, sample_rate, config=RastaPlpConfig(rasta=rasta))
    win, hop = round(0.025 * sample_rate), 0.01 * sample_rate
    padded = np.r_[np.zeros(win // 2), x, np.zeros(win)]
    frames = [padded[int(np.floor(k * hop + 0.5)) :][:win] for k in range(len(ours))]
    ref = _ellis_rastaplp(frames, sample_rate, rasta)
    # Measured max difference 2.4e-7 (float32 output) on cepstra up to 7.6.
    np.testing.assert_allclose(ours, ref, atol=1e-5)


# ---------------------------------------------------------------------------------------------
# Comparison with librosa
# ---------------------------------------------------------------------------------------------


def test_plp_agrees_with_librosa_energy_and_spectral_shape(utterances):
    u = utterances[0]
    x, sr = u.audio, u.sample_rate
    plp = rasta_plp(x, sr, config=PLP)
    rms = librosa.feature.rms(y=x, frame_length=400, hop_length=160, center=True)[0]
    assert len(rms) == len(plp)  # same frames: librosa centres frame k at k * hop too
    db = 20 * np.log10(np.maximum(rms, 1e-5))
    voiced = db > db.max() - 50
    # c0 (the model's log gain) tracks frame energy: r = 0.86 over the speech frames.
    assert np.corrcoef(plp[voiced, 0], db[voiced])[0, 1] > 0.75
    # c1 is the spectral tilt: r = -0.95 with librosa's spectral centroid and 0.93 with MFCC c1.
    centroid = librosa.feature.spectral_centroid(
        y=x, sr=sr, n_fft=512, hop_length=160, win_length=400
    )[0]
    assert np.corrcoef(plp[voiced, 1], centroid[voiced])[0, 1] < -0.85
    m = mfcc(x, sr)
    assert np.corrcoef(plp[voiced, 1], m[voiced, 1])[0, 1] > 0.85


def test_mfcc_matches_librosa_own_pipeline(utterances):
    u = utterances[1]
    x, sr = u.audio, u.sample_rate
    ours = mfcc(x, sr)
    # librosa frames are n_fft long with the 400-sample window centred in them: the same
    # samples as ours, so the power spectra are identical.
    mel = librosa.feature.melspectrogram(
        y=x, sr=sr, n_fft=512, hop_length=160, win_length=400, center=True,
        pad_mode="constant", n_mels=40,
    )
    ref = librosa.feature.mfcc(S=librosa.power_to_db(mel, amin=1e-10, top_db=None), n_mfcc=13).T
    assert ours.shape == ref.shape == (len(x) // 160 + 1, 13)
    np.testing.assert_allclose(ours, ref, atol=2e-3 * np.abs(ref).max())


# ---------------------------------------------------------------------------------------------
# Shape, timing, degenerate input
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "sample_rate, n_samples", [(16000, 16000), (16000, 16159), (16000, 1), (22050, 48000),
                               (44100, 441), (8000, 79), (48000, 123457)],
)
def test_frame_count_and_times(sample_rate, n_samples):
    x = np.random.default_rng(0).standard_normal(n_samples) * 0.1
    expected = int(np.floor(n_samples / (sample_rate * 0.01) + 1e-9)) + 1
    for f in (rasta_plp(x, sample_rate), rasta_plp(x, sample_rate, config=PLP),
              mfcc(x, sample_rate)):
        assert f.shape[0] == expected and f.dtype == np.float32
    assert rasta_plp(x, sample_rate).shape == (expected, 9)
    t = frame_times(expected)
    assert t.shape == (expected,) and t[0] == 0.0
    np.testing.assert_allclose(np.diff(t), 0.01)
    assert t[-1] <= n_samples / sample_rate < t[-1] + 0.01  # the last frame is in the signal
    assert np.allclose(frame_times(5, RastaPlpConfig(hop_s=0.02)), [0, 0.02, 0.04, 0.06, 0.08])


@pytest.mark.parametrize(
    "sample_rate, t",
    [(16000, 0.5033), (8000, 0.0), (22050, 25.0131), (44100, 3.3372), (48000, 1.9968)],
)
def test_frame_k_is_centred_at_k_hop(sample_rate, t):
    # A click at time t is loudest in the frame centred nearest t. At 22.05 kHz the hop is
    # 220.5 samples: a rounded hop would have drifted 5.7 frames by 25 s.
    x = np.zeros(int((t + 0.3) * sample_rate))
    x[int(round(t * sample_rate))] = 0.9
    expected = int(round(t / 0.01))
    assert np.argmax(rasta_plp(x, sample_rate, config=PLP)[:, 0]) == expected
    assert np.argmax(mfcc(x, sample_rate)[:, 0]) == expected


def _degenerate(sample_rate: int) -> dict[str, np.ndarray]:
    n = sample_rate  # 1 s
    t = np.arange(n) / sample_rate
    impulse = np.zeros(n)
    impulse[n // 3] = 1.0
    rng = np.random.default_rng(1)
    return {
        "digital silence": np.zeros(n),
        "10 ms": 0.1 * rng.standard_normal(sample_rate // 100),
        "one sample": np.array([0.5]),
        "impulse": impulse,
        "clipped sine": np.clip(20 * np.sin(2 * np.pi * 440 * t), -1, 1),
        "pure sine": np.sin(2 * np.pi * 1000 * t),
        "DC offset": 0.5 + 0.01 * np.sin(2 * np.pi * 200 * t),
        "full-scale DC": np.ones(n),
        "loud noise": np.clip(3 * rng.standard_normal(n), -1, 1),
        "float32 silence": np.zeros(n, dtype=np.float32),
    }


@pytest.mark.parametrize("sample_rate", [8000, 16000, 22050, 44100, 48000])
def test_output_is_always_finite(sample_rate):
    for name, x in _degenerate(sample_rate).items():
        n_frames = int(np.floor(len(x) / (sample_rate * 0.01) + 1e-9)) + 1
        for config in (RastaPlpConfig(), PLP, RastaPlpConfig(max_freq=3000.0, min_freq=100.0)):
            f = rasta_plp(x, sample_rate, config=config)
            assert f.shape == (n_frames, 9), name
            assert np.isfinite(f).all(), (name, config)
        assert np.isfinite(mfcc(x, sample_rate)).all(), name


def test_silence_and_short_input():
    assert rasta_plp(np.zeros(159), 16000).shape == (1, 9)  # under one hop: one frame
    assert rasta_plp(np.zeros(160), 16000).shape == (2, 9)  # 10 ms: frames at 0 and 10 ms
    # Digital silence is the dither floor's flat spectrum: the same in every frame.
    silent = rasta_plp(np.zeros(16000), 16000, config=PLP)
    assert np.ptp(silent, axis=0).max() < 1e-5


def test_more_cepstra_than_model_order_continue_the_recursion(speech):
    x, sr = speech
    nine = rasta_plp(x, sr, config=RastaPlpConfig(lifter_exp=0.0))
    twelve = rasta_plp(x, sr, config=RastaPlpConfig(n_coeffs=12, lifter_exp=0.0))
    np.testing.assert_allclose(twelve[:, :9], nine, rtol=1e-5, atol=1e-5)
    assert np.isfinite(twelve).all() and np.abs(twelve[:, 9:]).max() > 0


def test_lifter_scales_coefficient_i_by_i_to_the_power(speech):
    x, sr = speech
    raw = rasta_plp(x, sr, config=RastaPlpConfig(lifter_exp=0.0)).astype(np.float64)
    lifted = rasta_plp(x, sr).astype(np.float64)
    np.testing.assert_allclose(lifted, raw * np.r_[1.0, np.arange(1, 9) ** 0.6], rtol=1e-4,
                               atol=1e-5)


def test_a_minute_of_audio_gives_a_frame_every_10_ms():
    # Its speed is a benchmark's to measure, not a unit test's.
    x = np.random.default_rng(2).standard_normal(60 * 16000).astype(np.float32) * 0.1
    f = rasta_plp(x, 16000)
    assert f.shape == (6001, 9) and np.isfinite(f).all()


# ---------------------------------------------------------------------------------------------
# Phone discrimination on real speech
# ---------------------------------------------------------------------------------------------

_FRICATIVES = frozenset({"S", "SH", "Z", "ZH", "F", "V", "TH", "DH", "HH"})


def _phone_means(utterances, config):
    means = []
    for u in utterances:
        feats = rasta_plp(u.audio, u.sample_rate, config=config)
        for p in u.phones:
            means.append((p.phone, slice_frames(feats, p.start, p.end).mean(axis=0)))
    return means


def _leave_one_out_accuracy(means, label) -> tuple[float, int]:
    """Nearest-centroid accuracy, each segment held out of the centroids and the scaling."""
    keep = [(label(p), v) for p, v in means if label(p) is not None]
    y = np.array([lab for lab, _ in keep])
    x = np.array([v for _, v in keep], dtype=np.float64)
    classes = sorted(set(y))
    hits = 0
    for i in range(len(y)):
        train = np.arange(len(y)) != i
        mu, sd = x[train].mean(axis=0), x[train].std(axis=0)
        z = (x - mu) / sd
        centroids = np.array([z[train & (y == c)].mean(axis=0) for c in classes])
        hits += classes[int(np.argmin(((centroids - z[i]) ** 2).sum(axis=1)))] == y[i]
    return hits / len(y), len(y)


def test_rasta_plp_discriminates_phones(utterances):
    means = _phone_means(utterances, RastaPlpConfig())

    def broad(p):
        return "SIL" if p == "SIL" else "vowel" if p in VOWELS else (
            "fricative" if p in _FRICATIVES else None)

    # Vowels / fricatives / silence (72, 54, 13 segments): 0.88 measured, chance <= 0.52.
    accuracy, n = _leave_one_out_accuracy(means, broad)
    assert n >= 120 and accuracy > 0.75, accuracy

    # Eleven phones (94 segments): 0.88 measured, chance about 0.09.
    handful = {"IY", "AA", "AE", "EH", "S", "SH", "Z", "M", "N", "L", "SIL"}
    accuracy, n = _leave_one_out_accuracy(means, lambda p: p if p in handful else None)
    assert n >= 80 and accuracy > 0.7, accuracy


# ---------------------------------------------------------------------------------------------
# slice_frames
# ---------------------------------------------------------------------------------------------


def test_slice_frames_takes_centres_in_half_open_interval():
    feats = np.arange(20, dtype=np.float32)[:, None] * np.ones((1, 3), dtype=np.float32)
    rows = lambda s, e: slice_frames(feats, s, e)[:, 0].astype(int).tolist()  # noqa: E731
    assert rows(0.03, 0.07) == [3, 4, 5, 6]  # 0.07 excluded, 0.03 included
    assert rows(0.07, 0.10) == [7, 8, 9]  # float times exactly on centres
    assert rows(0.0, 10.0) == list(range(20))  # clipped to the features
    assert rows(0.025, 0.035) == [3]
    # No centre inside: the nearest to the midpoint, never empty.
    assert rows(0.031, 0.038) == [3]
    assert rows(0.0351, 0.0399) == [4]
    assert rows(0.05, 0.05) == [5]  # zero duration
    assert rows(0.195, 0.1999) == [19]  # past the last centre
    assert rows(-0.004, 0.0) == [0]
    view = slice_frames(feats, 0.0, 0.05)
    assert view.shape == (5, 3) and np.shares_memory(view, feats)


def test_slice_frames_on_real_phones(utterances):
    u = utterances[2]
    feats = rasta_plp(u.audio, u.sample_rate)
    times = frame_times(len(feats))
    for p in u.phones:
        curve = slice_frames(feats, p.start, p.end)
        assert len(curve) >= 1
        inside = np.flatnonzero((times >= p.start - 1e-9) & (times < p.end - 1e-9))
        if len(inside):
            np.testing.assert_array_equal(curve, feats[inside[0] : inside[-1] + 1])
    total = sum(len(np.flatnonzero((times >= p.start) & (times < p.end))) for p in u.phones)
    assert total == len(feats)  # the phones tile the frames: each frame in one phone


def test_slice_frames_with_another_hop():
    feats = np.arange(10, dtype=np.float64)[:, None]
    assert slice_frames(feats, 0.04, 0.09, hop_s=0.02)[:, 0].tolist() == [2, 3, 4]


# ---------------------------------------------------------------------------------------------
# Errors
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "audio, sample_rate, match",
    [
        (np.zeros((1000, 2)), 16000, "audio"),
        (np.zeros(0), 16000, "audio"),
        (np.zeros(1000, dtype=np.int16), 16000, "audio"),
        (np.zeros(1000), 7999, "sample_rate"),
        (np.zeros(1000), 96000, "sample_rate"),
        (np.zeros(1000), 16000.0, "sample_rate"),
        (np.zeros(1000), True, "sample_rate"),
    ],
)
def test_bad_arguments(audio, sample_rate, match):
    with pytest.raises(ParameterError, match=match):
        rasta_plp(audio, sample_rate)
    with pytest.raises(ParameterError, match=match):
        mfcc(audio, sample_rate)


def test_non_finite_audio_is_bad_data():
    x = np.zeros(1000)
    x[10] = np.nan
    with pytest.raises(DataError, match="non-finite"):
        rasta_plp(x, 16000)
    with pytest.raises(DataError, match="non-finite"):
        mfcc(x, 16000)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"win_s": 0.0}, "win_s"),
        ({"hop_s": -0.01}, "hop_s"),
        ({"hop_s": float("nan")}, "hop_s"),
        ({"model_order": 0}, "model_order"),
        ({"model_order": 8.0}, "model_order"),
        ({"n_coeffs": 0}, "n_coeffs"),
        ({"rasta": 1}, "rasta"),
        ({"lifter_exp": -1.0}, "lifter_exp"),
        ({"min_freq": -5.0}, "min_freq"),
        ({"min_freq": 500.0, "max_freq": 400.0}, "max_freq"),
    ],
)
def test_bad_config(kwargs, match):
    with pytest.raises(ParameterError, match=match):
        RastaPlpConfig(**kwargs)


def test_config_checked_against_the_sample_rate():
    x = np.zeros(8000)
    with pytest.raises(ParameterError, match="max_freq"):
        rasta_plp(x, 8000, config=RastaPlpConfig(max_freq=5000.0))
    with pytest.raises(ParameterError, match="model_order"):
        rasta_plp(x, 8000, config=RastaPlpConfig(model_order=17))  # 17 bands at 8 kHz
    assert rasta_plp(x, 8000, config=RastaPlpConfig(model_order=16)).shape == (101, 9)
    with pytest.raises(ParameterError, match="win_s"):
        rasta_plp(x, 8000, config=RastaPlpConfig(win_s=0.0005))
    with pytest.raises(ParameterError, match="config"):
        rasta_plp(x, 8000, config={"rasta": False})
    with pytest.raises(ParameterError, match="n_mfcc"):
        mfcc(x, 8000, n_mfcc=0)


def test_slice_frames_errors():
    feats = np.zeros((10, 9))
    with pytest.raises(ParameterError, match="end"):
        slice_frames(feats, 0.05, 0.04)
    with pytest.raises(ParameterError, match="features"):
        slice_frames(np.zeros((0, 9)), 0.0, 0.1)
    with pytest.raises(ParameterError, match="features"):
        slice_frames(np.zeros(10), 0.0, 0.1)
    with pytest.raises(ParameterError, match="start"):
        slice_frames(feats, float("nan"), 0.1)
    with pytest.raises(ParameterError, match="hop_s"):
        slice_frames(feats, 0.0, 0.1, hop_s=0)
    with pytest.raises(DataError, match="outside"):
        slice_frames(feats, 0.5, 0.6)  # 10 frames span 0 .. 0.09 s
    with pytest.raises(ParameterError, match="n_frames"):
        frame_times(-1)


@pytest.mark.parametrize("sample_rate, n_fft", [(16000, 512), (22050, 1024), (8000, 256)])
def test_mel_filters_and_dct_are_librosas(sample_rate, n_fft):
    """mfcc() computes librosa's mel filterbank and DCT itself (NumPy only)."""
    import scipy.fft

    from ingest.speech.features import dct_ii, slaney_mel_filters

    np.testing.assert_allclose(
        slaney_mel_filters(sample_rate, n_fft, 40),
        librosa.filters.mel(sr=sample_rate, n_fft=n_fft, n_mels=40, dtype=np.float64),
        rtol=1e-10, atol=1e-12)
    x = np.random.default_rng(0).standard_normal((40, 7))
    np.testing.assert_allclose(dct_ii(40) @ x, scipy.fft.dct(x, type=2, norm="ortho", axis=0),
                               atol=1e-12)


def test_mfcc_bases_built_once_per_rate_and_size_give_the_same_coefficients():
    # The mel filters and DCT rows are kept per (rate, FFT size, n_mfcc): a rate or size
    # met again gives its first coefficients bit for bit, and another gets its own.
    from ingest.speech.features import mfcc

    rng = np.random.default_rng(3)
    audio = rng.normal(0, 0.1, 8000).astype(np.float32)
    first = {(sr, n): mfcc(audio, sr, n_mfcc=n) for sr in (16000, 22050) for n in (13, 20)}
    for (sr, n), coeffs in first.items():
        again = mfcc(audio, sr, n_mfcc=n)
        assert again.shape[1] == n
        np.testing.assert_array_equal(again, coeffs)
    np.testing.assert_allclose(first[16000, 13], first[16000, 20][:, :13], rtol=1e-5,
                               atol=1e-4)
    assert first[16000, 13].shape != first[22050, 13].shape
