"""``--low-latency``'s posteriors: a frame is sent before hama's posteriors of it settle,
and they settle one update later (docs/results/live.md, "The low-latency setting")."""

from __future__ import annotations

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def speech():
    from ingest.speech import ctc
    from ingest.speech.espeak import speak

    if not ctc.available():
        pytest.skip("the hama phone engine is not installed")
    u = speak("Bring the blue box to the table, please.")
    return u.audio.astype(np.float32), u.sample_rate


def test_low_latency_frames_are_sent_before_their_posteriors_settle(speech):
    from animegraph.live.frontend import FRAME_RATE, PosteriorTrack
    from animegraph.live.stream import LOW_LATENCY

    audio, sr = speech
    track = PosteriorTrack(sr, context_s=LOW_LATENCY["posterior_context_ms"] / 1000,
                           settle_s=LOW_LATENCY["settle_ms"] / 1000)
    hop = int(round(LOW_LATENCY["hop_ms"] / 1000 * sr))
    lookahead_s = LOW_LATENCY["lookahead_ms"] / 1000
    peak, before, settled_before, changed, final = 0.0, None, 0, 0, {}
    for end in range(hop, len(audio) + 1, hop):
        peak = max(peak, float(np.abs(audio[end - hop:end]).max()))
        track.update(audio, 0, end, peak)
        # hama's frames the stream may send now: those the look-ahead has passed
        sendable = math.floor((end / sr - lookahead_s) * FRAME_RATE)
        if sendable > 0:
            assert track.settled < sendable  # sent while their posteriors are tentative
            # ... and settled once (settle - look-ahead) more is heard: one hop later
            # (a frame more where the times round down)
            lag = (LOW_LATENCY["settle_ms"] - LOW_LATENCY["lookahead_ms"]) / 1000 * FRAME_RATE
            assert track.settled >= sendable - round(lag) - 1
        rows = track.posteriors(0, track.frames)
        if before is not None:  # the last update's tentative rows, computed again
            old, new = before[settled_before:], rows[settled_before:len(before)]
            assert len(old) and old.shape == new.shape
            changed += int(not np.allclose(old, new))
        for k in range(track.settled):  # settled rows never change
            if k in final:
                np.testing.assert_array_equal(rows[k], final[k])
            else:
                final[k] = rows[k].copy()
        before, settled_before = rows, track.settled
    assert changed > 0  # the frames sent were settled later, with more audio heard
    assert len(final) > 0.8 * len(audio) / sr * FRAME_RATE
