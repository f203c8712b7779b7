"""Speech pushed in as it is spoken, facial motion out frame by frame (:class:`Stream`).

The offline audio-only default (:func:`animegraph.synthesis.synthesize`: phones heard by
hama, each phone the mean of its k best animes, averaged with the guide's predicted
motion) needs the whole utterance: the phone model hears all of its input, the search
and k-best cross-fading look at the next phone, the low-pass runs forward and backward.
Live, each update re-synthesizes a bounded *window* with the same code:

* the window runs from ``context_ms`` before the first frame not yet sent to the newest
  sample (so ``context + hop + lookahead``); older audio is dropped;
* hama's phone posteriors are not computed on the window: the stream keeps them for
  every 20 ms of audio, computed once (:class:`animegraph.live.frontend.PosteriorTrack`:
  each update the model hears only the frames not settled yet and a context before
  them), and hands the window's rows to :mod:`ingest.speech.ctc`
  (:func:`~ingest.speech.ctc.remember`); ppg-ridge reads them as its posteriorgram, and
  the window's phones are recognised as offline's default recognises an utterance's
  (:func:`ingest.speech.engines.recognize_auto`: hama names them from those posteriors,
  and PocketSphinx places them on the window's audio; at ``--low-latency`` hama places
  them too, CTC greedy decoding, :func:`ingest.speech.ctc.recognize`). A window starts
  on a 20 ms frame (when the frame rate allows), so that its rows are the track's;
* the window is synthesized as the offline path synthesizes an utterance (k-best
  :data:`~animegraph.synthesis.path.AUDIO_ONLY_K_BEST`, no context ranking, the guide
  blended) from those phones given as labels, except that the guide's share is
  :data:`LIVE_GUIDE_SHARE` on a database of one recording session (offline's 0.5 on
  several: :func:`default_guide_share`) and each phone's choice of
  animes is made once (:mod:`animegraph.live.window`): a phone found again in the next
  window (same label, boundaries within 20 ms) keeps its k best animes and their
  time-warps, and only the new phones are scored by DTW and warped;
* with a transcript (``text``) the window's phones are the transcript's, aligned to the
  posteriors as the audio arrives (:mod:`animegraph.live.transcript`);
* the frames of the window up to ``lookahead_ms`` before its end are sent: a frame is
  sent once the audio ``lookahead`` after it has arrived, and it never changes after. The
  first :data:`FADE_FRAMES` frames of an update are cross-faded from what the previous
  window had for them, so that two windows meet without a step.

hama hears the audio at one level, set by a reference peak (:meth:`Stream.level`): offline
the clip's own peak; live the loudest sample heard so far, but never less than what speech
:data:`SPEECH_OVER_NOISE_DB` above the quietest 20 ms heard would reach. At a stream's
start, before any speech, the loudest sample is the room's noise: scaled to the speech's
level, hama heard it as phones, and the leading silence moved the mouth.

A window whose loudest sample lies :data:`QUIET_DB` below that reference (or is
silent) is a pause: hama would hear the noise at full level (it hears every input at one
level), so no phone is looked for; its frames ease into the database's rest pose (the
mean of its silence animes). A window in which hama hears only silence is synthesized
as offline synthesis synthesizes an utterance's silences (its silence animes and the
guide), not as the rest pose: offline the leading silence moves, as the recording does
(GRID's speakers open their mouth before the first word), and the rest pose was most of
live's loss in each clip's first second (docs/results/live.md).

Frame ``k`` is at ``k / fps`` seconds in the input's clock (its first sample at 0), in the
database's channel layout ``(n_frames, n_channels)``.
"""

from __future__ import annotations

import time
from collections import Counter
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from animegraph.live.frontend import CONTEXT_S, FRAME_RATE, SETTLE_S, LoudLevel, PosteriorTrack
from animegraph.live.transcript import TranscriptTrack, window_segments
from animegraph.live.window import PhoneMemory, window_motion
from db.errors import DataError, ParameterError

#: Look-ahead (ms) by default: the audio after a frame that is heard before it is sent.
DEFAULT_LOOKAHEAD_MS = 120.0
#: Audio (ms) between two updates by default.
DEFAULT_HOP_MS = 80.0
#: Audio (ms) before the first unsent frame that each window re-synthesizes, by default
#: (hama's own context is the posterior track's, :data:`animegraph.live.frontend.CONTEXT_S`;
#: 300 ms here followed the offline output as closely as 600 ms, docs/results/live.md).
DEFAULT_CONTEXT_MS = 300.0
#: ``animegraph live``'s default setting, and ``--low-latency``'s: frames sooner (a 40 ms
#: look-ahead and hop; hama hearing 300 ms of context, a frame settled 80 ms after it;
#: hama placing its phones, without PocketSphinx's share of an update)
#: for a mouth that follows the offline output less closely (docs/results/live.md,
#: "Latency" and "Quality against the offline default"). Its hama is on each update's
#: critical path, and costs 43 ms per second of audio it hears (one thread, no state
#: kept between calls): at a 40 ms hop, 600 ms of context would cost 14 ms more an update
#: and more than a core in all, for +0.007 on GRID; settling a frame 80 ms after it
#: (after the frame is sent: the windows after it hear it settled) costs 2.4 ms, for
#: +0.005 on GRID and +0.007 on FACEGOOD. Most of this setting's loss against the
#: default's at the same look-ahead is the hop, not hama (the results page, "The
#: low-latency setting: hama's context and its cost").
DEFAULT_SETTING = {"lookahead_ms": DEFAULT_LOOKAHEAD_MS, "hop_ms": DEFAULT_HOP_MS}
LOW_LATENCY = {"lookahead_ms": 40.0, "hop_ms": 40.0, "posterior_context_ms": 300.0,
               "settle_ms": 80.0, "phones_engine": "hama"}
#: The guide's share of each window's motion by default for a database of one recording
#: session (:func:`default_guide_share`; ``Stream(guide_share=...)``, ``--guide-share``);
#: offline keeps its plain mean (0.5, :data:`animegraph.synthesis.guide.GUIDE_BLEND`). In a
#: short window the animes are less reliable than offline: chosen on a calibration split
#: of the GRID database clips (one speaker: every 8th of the GRID split's 640, streamed
#: against a database of the other 560; never the held-out clips) among 0.5, 0.65, 0.8
#: and 1.0, where 0.65 beat 0.5 at both settings by more than twice the paired standard
#: error and 0.8 did no better than 0.65 (docs/results/live.md, "The guide's share, live").
LIVE_GUIDE_SHARE = 0.65
#: Input rates accepted (Hz): hama resamples to 16 kHz; below 8 kHz speech loses the
#: band its phones need, above 96 kHz is not a microphone's or a voice's rate.
MIN_RATE, MAX_RATE = 8000, 96000
#: A window this many dB below the reference peak (:meth:`Stream.level`) is a pause.
QUIET_DB = 40.0
#: The reference peak is at least this many dB over the noise floor (the quietest 20 ms
#: heard, by its peak), at most full scale, so that the noise before the first word is
#: heard quiet; so is the loud level of ppg-ridge's loudness feature over the quietest
#: 20 ms by its RMS (:class:`animegraph.live.frontend.LoudLevel`). Set below what speech
#: reaches (GRID s1's 640 database clips: their peak 37-47 dB over their quietest 20 ms,
#: their frames' 95th-percentile RMS 33-43 dB over the quietest frame's, 5th-95th
#: percentile), so that the reference is not above the speech's own; not tuned.
SPEECH_OVER_NOISE_DB = 30.0
#: Audio (s) whose peak is one step of the noise floor's running minimum.
FLOOR_FRAME_S = 0.02
#: Audio waiting (ms) beyond which one update hears all of it at once (the stream has
#: fallen behind: it catches up, with a longer window, instead of lagging ever more).
DEFAULT_BACKLOG_MS = 400.0
#: Threads an update runs at once by default (numba's DTW pool, BLAS). One: with two,
#: OpenBLAS's threads (which wait spinning) and the DTW's took a quarter more CPU for
#: little less wall time (docs/results/live.md, "CPU").
DEFAULT_THREADS = 1
#: How a window's phones are recognised (``Stream(phones_engine=...)``, ``--phones-engine``):
#: ``"hama"`` names and places them (CTC greedy decoding of the track's posteriors);
#: ``"auto"``, offline's default (:mod:`ingest.speech.engines`), has PocketSphinx place
#: hama's phones on the window's audio. ``"auto"`` by default: paired, it gained on
#: talkingface (within and across speakers) and was level on GRID and FACEGOOD, for about
#: a tenth more CPU (docs/results/live.md, "Placing the phones").
LIVE_PHONE_ENGINES = ("hama", "auto")
DEFAULT_PHONE_ENGINE = "auto"
#: Frames at the start of an update cross-faded from the previous window's estimate.
FADE_FRAMES = 3
#: With ``emotion="auto"``: the speech is classified again every this many seconds, over
#: the last :data:`AUTO_SPAN_S` seconds.
AUTO_EVERY_S = 2.0
AUTO_SPAN_S = 3.0


@dataclass(frozen=True)
class Frames:
    """Motion frames sent by one call of :meth:`Stream.push` or :meth:`Stream.close`.

    Attributes
    ----------
    first : int
        Index of the first frame (frames are numbered from the stream's start).
    motion : np.ndarray, shape (n_frames, n_channels)
        In the database's channels.
    fps : float
    heard_s : float
        Seconds of audio heard when they were computed.
    """

    first: int
    motion: np.ndarray
    fps: float
    heard_s: float

    def __len__(self) -> int:
        return len(self.motion)

    @property
    def indices(self) -> np.ndarray:
        """Frame indices, shape (n_frames,)."""
        return np.arange(self.first, self.first + len(self.motion))

    @property
    def times(self) -> np.ndarray:
        """Each frame's time (s) in the input's clock, shape (n_frames,)."""
        return self.indices / self.fps


@dataclass
class Stats:
    """What a stream did: updates, their wall and CPU time (in all and each: ``update_wall``,
    ``update_cpu``, s), pauses, updates that caught up, warnings by kind."""

    updates: int = 0
    wall_s: float = 0.0
    cpu_s: float = 0.0
    update_wall: list = field(default_factory=list)
    update_cpu: list = field(default_factory=list)
    pauses: int = 0
    caught_up: int = 0
    warnings: Counter = field(default_factory=Counter)


class Stream:
    """Facial motion for speech pushed in chunks, sent with a bounded look-ahead.

    Parameters
    ----------
    model : animegraph.synthesis.Model or path
        The motion database (a path is loaded).
    sample_rate : int
        Of the pushed samples, in [:data:`MIN_RATE`, :data:`MAX_RATE`] Hz.
    lookahead_ms : float
        Audio heard after a frame before it is sent (>= 0). Latency is at least this.
    hop_ms : float
        Audio between two updates (> 0): smaller updates more often, at more CPU.
    context_ms : float
        Audio before the first unsent frame that each window hears again (>= 100).
    emotion : None, str or dict
        As :func:`animegraph.synthesis.synthesize`: a name, a mix, ``"auto"`` (classified
        every :data:`AUTO_EVERY_S` s on the last :data:`AUTO_SPAN_S` s); changed while
        running by :meth:`set_emotion`.
    guide : baseline model, tuple of them, or None
        The guide (:mod:`animegraph.synthesis.guide`); the offline audio-only default is
        the mean of mu-mlp and ppg-ridge (:func:`stored_guide` reads them from the
        database). None: the animes alone.
    guide_share : float in [0, 1] or None
        The guide's share of each window's motion (1: the guide alone). None: by the
        database (:func:`default_guide_share`: :data:`LIVE_GUIDE_SHARE` for one recording
        session, offline's 0.5 for several).
    k_best : int
        Animes averaged per phone.
    backlog_ms : float or None
        Audio waiting beyond which one update hears all of it (catching up when updates
        take longer than the audio they cover); None: never (each update hears one hop,
        whatever the chunks pushed: the frames do not depend on how the audio was cut).
    posterior_context_ms, settle_ms : float
        hama's phone posteriors are computed once per 20 ms frame
        (:class:`animegraph.live.frontend.PosteriorTrack`): the model hears this much audio
        before the first unsettled frame, and a frame is settled once this much audio
        after it has been heard.
    text : str or TranscriptTrack, optional
        What the speech says (a text-to-speech voice knows it), or a new track of it
        (to set its options, or to watch what it is fed): the window's phones are
        the transcript's, aligned to the posteriors as the audio arrives
        (:class:`animegraph.live.transcript.TranscriptTrack`) and ranked by phonetic
        context first, as offline synthesis with a transcript does
        (:mod:`animegraph.synthesis.path`); ``guide`` is still blended (offline it is
        not: live, without it, the mouth followed the recording much less closely). A
        transcript that stops fitting the speech is said once (``stats.warnings``) and
        the phones are recognised from there on.
    threads : int or None
        Threads an update may run at once: the DTW's (numba's, for the updating thread)
        and BLAS's (the whole process' while an update runs). None: as many as the
        libraries take (the cores). hama hears a window in one piece, on one thread.
    phones_engine : {"hama", "auto"}
        How the window's phones are recognised (:data:`LIVE_PHONE_ENGINES`): ``"hama"``
        names and places them; ``"auto"`` (the default) as offline's default engine, hama
        naming them and PocketSphinx placing them on the window's audio (hama's own
        timing where PocketSphinx finds no path). A transcript's phones are placed by
        its path either way.

    Raises
    ------
    ParameterError
        On an unsupported rate, a look-ahead, hop, context or guide share out of
        range, an unknown ``phones_engine``, or an empty ``text``.
    DataError
        A ``text`` with no pronounceable word.
    """

    def __init__(self, model, *, sample_rate: int = 16000,
                 lookahead_ms: float = DEFAULT_LOOKAHEAD_MS, hop_ms: float = DEFAULT_HOP_MS,
                 context_ms: float = DEFAULT_CONTEXT_MS, emotion=None, guide=None,
                 guide_share: float | None = None, k_best: int | None = None,
                 backlog_ms: float | None = DEFAULT_BACKLOG_MS,
                 posterior_context_ms: float = CONTEXT_S * 1000,
                 settle_ms: float = SETTLE_S * 1000, text: str | None = None,
                 threads: int | None = DEFAULT_THREADS,
                 phones_engine: str = DEFAULT_PHONE_ENGINE) -> None:
        from animegraph.synthesis import Model
        from animegraph.synthesis.path import AUDIO_ONLY_K_BEST

        check_rate(sample_rate)
        for name, value, low in (("lookahead_ms", lookahead_ms, 0.0), ("hop_ms", hop_ms, 1.0),
                                 ("context_ms", context_ms, 100.0),
                                 ("posterior_context_ms", posterior_context_ms, 0.0),
                                 ("settle_ms", settle_ms, 0.0)):
            if not (isinstance(value, int | float) and np.isfinite(value) and value >= low):
                raise ParameterError(f"{name} must be a number >= {low:g}, got {value!r}")
        if guide_share is not None and (isinstance(guide_share, bool) or not (
                isinstance(guide_share, int | float) and 0.0 <= guide_share <= 1.0)):
            raise ParameterError(f"guide_share must be a number in [0, 1], got "
                                 f"{guide_share!r}")
        if threads is not None and (isinstance(threads, bool) or not isinstance(
                threads, int | np.integer) or threads < 1):
            raise ParameterError(f"threads must be a whole number >= 1 or None, got "
                                 f"{threads!r}")
        if phones_engine not in LIVE_PHONE_ENGINES:
            raise ParameterError(f"phones_engine: expected one of "
                                 f"{', '.join(LIVE_PHONE_ENGINES)}, got {phones_engine!r}")
        self.phones_engine = phones_engine
        self.threads = None if threads is None else int(threads)
        self.model = model if isinstance(model, Model) else Model.load(model)
        self.sample_rate = int(sample_rate)
        self.lookahead_s = lookahead_ms / 1000.0
        self.hop_s = hop_ms / 1000.0
        self.context_s = context_ms / 1000.0
        self.guide = guide
        self.guide_share = float(default_guide_share(self.model) if guide_share is None
                                 else guide_share)
        self.backlog_s = None if backlog_ms is None else backlog_ms / 1000.0
        self.k_best = AUDIO_ONLY_K_BEST if k_best is None else int(k_best)
        self.fps = float(self.model.graph.fps)
        self.names = self.model.names
        self.stats = Stats()
        self._emotion = None
        self._auto = False
        self._auto_at = -np.inf
        self._auto_choice: str | None = None
        self.set_emotion(emotion)
        self._rest = rest_pose(self.model)
        self._buffer = np.zeros(0, dtype=np.float32)
        self._buffer_start = 0  # sample index of _buffer[0]
        self._heard = 0  # samples pushed
        self._peak = 0.0  # loudest sample heard
        self._floor = np.inf  # the quietest FLOOR_FRAME_S heard, by its peak
        self._floor_at = 0  # samples of the input measured for the floor
        self._loud = LoudLevel(SPEECH_OVER_NOISE_DB)  # ppg-ridge's loud level
        self._sent = 0  # frames sent
        self._updated_at = 0  # samples heard at the last update
        self._last = self._rest.copy()  # the last frame sent
        self._tentative: tuple[int, np.ndarray] | None = None  # unsent frames of a window
        self._track = PosteriorTrack(self.sample_rate, context_s=posterior_context_ms / 1000,
                                     settle_s=settle_ms / 1000)
        if isinstance(text, TranscriptTrack) and (text.frames or text.frame_rate != FRAME_RATE):
            raise ParameterError(f"text: a transcript track must be new and at "
                                 f"{FRAME_RATE} frames/s")
        self._transcript = (text if isinstance(text, TranscriptTrack) or text is None
                            else TranscriptTrack(text, FRAME_RATE))
        self._memory = PhoneMemory()  # each phone's choice of animes, made once
        self._closed = False

    # -- control ---------------------------------------------------------------------------

    def set_emotion(self, emotion) -> None:
        """Change the emotion from the next update on (a name, a mix, ``"auto"``, None)."""
        from animegraph.emotion.control import AUTO, check_names, parse_emotion

        spec = parse_emotion(emotion)
        spec = check_names(spec, self.model.emotion_model, self.model.graph.emotions)
        self._auto = spec == AUTO
        if self._auto and self.model.emotion_model is None:
            raise DataError("emotion auto needs the database's emotion classifier, which "
                            "it does not have")
        self._emotion = None if self._auto else spec
        self._auto_at = -np.inf

    @property
    def emotion(self):
        """The emotion synthesized now (for ``"auto"``, the last one classified)."""
        return self._auto_choice if self._auto else self._emotion

    @property
    def heard_s(self) -> float:
        """Seconds of audio pushed."""
        return self._heard / self.sample_rate

    @property
    def sent(self) -> int:
        """Frames sent so far."""
        return self._sent

    # -- audio in, frames out --------------------------------------------------------------

    def push(self, samples: np.ndarray) -> Frames:
        """Hear ``samples`` (shape (n,), float in [-1, 1] or integer PCM) and return the
        frames that can now be sent (possibly none)."""
        if self._closed:
            raise ParameterError("the stream is closed")
        x = as_mono_float(samples)
        self._buffer = np.concatenate([self._buffer, x])
        self._heard += len(x)
        if len(x):
            self._peak = max(self._peak, float(np.max(np.abs(x))))
            self._measure_floor()
        hop = int(round(self.hop_s * self.sample_rate))
        out = []
        while self._heard - self._updated_at >= hop:
            waiting = (self._heard - self._updated_at) / self.sample_rate
            if self.backlog_s is not None and waiting > self.backlog_s:
                self.stats.caught_up += 1
                out.append(self._update(self._heard, final=False))
            else:
                out.append(self._update(self._updated_at + hop, final=False))
        return join(out, self._empty())

    def level(self) -> float:
        """The reference peak hama's input is scaled to (and pauses are judged by): the
        loudest sample heard so far, at least :data:`SPEECH_OVER_NOISE_DB` over the noise
        floor (at most full scale)."""
        floor = 0.0 if not np.isfinite(self._floor) else self._floor
        return max(self._peak, min(1.0, floor * 10 ** (SPEECH_OVER_NOISE_DB / 20)))

    def _measure_floor(self) -> None:
        """The noise floor (the least peak of the whole FLOOR_FRAME_S spans heard) and the
        spans' RMS, for ppg-ridge's loud level (each span's own: however the audio was cut
        into chunks, the same)."""
        n = int(round(FLOOR_FRAME_S * self.sample_rate))
        end = self._buffer_start + len(self._buffer)
        count = (end - self._floor_at) // n
        if count <= 0:
            return
        a = self._floor_at - self._buffer_start
        spans = self._buffer[a: a + count * n].reshape(count, n).astype(np.float64)
        self._floor = min(self._floor, float(np.abs(spans).max(axis=1).min()))
        self._loud.add(np.sqrt((spans ** 2).mean(axis=1)))
        self._floor_at += count * n

    def close(self) -> Frames:
        """Send the frames left, up to the end of the audio (no more look-ahead)."""
        if self._closed:
            return self._empty()
        frames = self._update(self._heard, final=True)
        self._closed = True
        self._end_transcript()
        return frames

    # -- one update ------------------------------------------------------------------------

    def _empty(self) -> Frames:
        return Frames(self._sent, np.zeros((0, len(self.names))), self.fps, self.heard_s)

    def _update(self, end: int, *, final: bool) -> Frames:
        """Send the frames that the audio up to sample ``end`` allows."""
        wall, cpu = time.perf_counter(), time.process_time()
        self._updated_at = end
        end_s = end / self.sample_rate
        if final:
            target = int(round(end_s * self.fps))
        else:
            target = int(np.floor((end_s - self.lookahead_s) * self.fps + 1e-9)) + 1
        target = min(target, int(round(end_s * self.fps)))
        if target <= self._sent:
            return self._empty()
        with capped_threads(self.threads):
            out, first_sent = self._frames(end, target)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        self.stats.updates += 1
        self.stats.wall_s += wall
        self.stats.cpu_s += cpu
        self.stats.update_wall.append(wall)
        self.stats.update_cpu.append(cpu)
        return Frames(first_sent, out, self.fps, end_s)

    def _frames(self, end: int, target: int) -> tuple[np.ndarray, int]:
        """The frames up to ``target`` not sent yet, from the audio up to sample ``end``,
        and the index of the first."""
        first = self._on_posterior_frame(
            max(0, int(np.floor((self._sent / self.fps - self.context_s) * self.fps))))
        self._track.update(self._buffer, self._buffer_start, end, self.level())
        self._follow_transcript()
        motion = self._window(first, end)  # frames first, first + 1, ... (may end short)
        if len(motion) < target - first:  # rounding at the end: hold the last frame
            pad = motion[-1:] if len(motion) else self._last[None]
            motion = np.concatenate([motion, np.repeat(pad, target - first - len(motion), 0)])
        out = motion[self._sent - first: target - first].copy()
        out = self._fade(out)
        self._tentative = (target, motion[target - first:])
        self._sent, self._last = target, out[-1].copy()
        first_sent = target - len(out)
        self._drop_old()
        return out, first_sent

    def _follow_transcript(self) -> None:
        """Extend the transcript's path over the posteriors not fixed on it yet; once it
        stops fitting the speech, say so (once) and recognise the phones instead."""
        script = self._transcript
        if script is None:
            return
        if script.failed is None:
            first = script.fixed
            rows = self._track.posteriors(first, self._track.frames - first)
            script.update(np.log(np.maximum(rows, 1e-30)), first)
        if script.failed is not None:
            self.stats.warnings[script.failed[:80]] += 1
            self._transcript = None

    def _end_transcript(self) -> None:
        """The speech has ended: test the transcript's fit over all of it (a short
        utterance never had the seconds the running test needs) and say if it failed;
        the frames sent followed it (:meth:`animegraph.live.transcript.TranscriptTrack.
        finish`)."""
        script = self._transcript
        if script is None:
            return
        first = script.fixed
        rows = self._track.posteriors(first, self._track.frames - first)
        script.finish(np.log(np.maximum(rows, 1e-30)), first)
        if script.failed is not None:
            self.stats.warnings[script.failed[:80]] += 1

    def _on_posterior_frame(self, first: int) -> int:
        """The latest motion frame at or before ``first`` that starts a 20 ms posterior
        frame too (so that the window's posteriors are the track's rows, not shifted),
        if one lies within a second; else ``first``."""
        for k in range(first, max(-1, first - int(self.fps) - 1), -1):
            pos = k * FRAME_RATE / self.fps
            if abs(pos - round(pos)) < 1e-6:
                return k
        return first

    def _fade(self, out: np.ndarray) -> np.ndarray:
        """The first frames of ``out`` eased from the previous window's estimate."""
        prev = self._tentative
        if prev is not None and prev[0] == self._sent and len(prev[1]):
            n = min(FADE_FRAMES, len(out), len(prev[1]))
            w = (np.arange(1, n + 1) / (FADE_FRAMES + 1))[:, None]
            out[:n] = (1 - w) * prev[1][:n] + w * out[:n]
        return out

    def _window(self, first: int, end: int) -> np.ndarray:
        """Motion of the window from frame ``first`` to sample ``end``, shape
        (n_frames, n_channels): synthesized as offline, or the rest pose in a pause."""
        start = int(round(first / self.fps * self.sample_rate))
        audio = self._buffer[max(0, start - self._buffer_start): end - self._buffer_start]
        n = int(round(len(audio) / self.sample_rate * self.fps))
        peak = float(np.max(np.abs(audio))) if len(audio) else 0.0
        if peak <= self.level() * 10 ** (-QUIET_DB / 20) or peak <= 1e-4:
            return self._pause(n)
        start_s = max(start, self._buffer_start) / self.sample_rate  # where the audio begins
        try:
            return self._synthesize(audio, n, start_s)
        except DataError as exc:  # e.g. nothing but silence heard in the window
            self.stats.warnings[str(exc).split(":")[0][:80]] += 1
            return self._pause(n)

    def _pause(self, n: int) -> np.ndarray:
        self.stats.pauses += 1
        return np.repeat(self._rest[None], n, axis=0)

    def _synthesize(self, audio: np.ndarray, n: int, start_s: float) -> np.ndarray:
        """The window's motion (its audio begins at ``start_s``); its phones and the
        guide's posteriorgram from the track's posteriors, the model not run again."""
        from animegraph.baselines.ppg_forward import loud_level
        from animegraph.synthesis.path import KNOWN_PHONES_CONTEXT
        from ingest.speech import ctc
        from ingest.speech.engines import recognizer

        first_posterior = int(round(start_s * FRAME_RATE))
        count = int(np.ceil(len(audio) / self.sample_rate * FRAME_RATE - 1e-9))
        probs = self._track.posteriors(first_posterior, count)
        ctc.remember(audio, self.sample_rate, probs)
        if self._transcript is not None:  # the transcript's phones, placed by its path
            segments = window_segments(self._transcript, probs, first_posterior, audio,
                                       self.sample_rate)
        else:  # hama's phones from the posteriors remembered above
            segments = recognizer(self.phones_engine)(audio, self.sample_rate)
        # Known phones are ranked by phonetic context first, as offline (synthesis.path);
        # unlike offline the guide stays blended: a short window's animes alone followed
        # the recording much less closely (docs/results/live.md, "With a transcript").
        context = self._transcript is not None and KNOWN_PHONES_CONTEXT
        # ppg-ridge's loudness relative to all the stream has heard, as offline to the
        # whole clip's: not to the window's own loud level (LoudLevel).
        with loud_level(self._loud.level()):
            motion, warnings = window_motion(
                self.model, audio, self.sample_rate, segments, start_s, memory=self._memory,
                k_best=self.k_best, emotion=self._emotion_for(audio), context=context,
                guide=self.guide, guide_share=self.guide_share)
        for warning in warnings:
            self.stats.warnings[warning[:80]] += 1
        return motion

    def _emotion_for(self, audio: np.ndarray):
        """The emotion of this update: as set, or (``auto``) the speech's, classified
        again every :data:`AUTO_EVERY_S` seconds."""
        if not self._auto:
            return self._emotion
        if self.heard_s - self._auto_at >= AUTO_EVERY_S:
            from animegraph.emotion.control import AUTO, resolve_emotion

            span = self._buffer[-int(AUTO_SPAN_S * self.sample_rate):]
            try:
                choice = resolve_emotion(AUTO, self.model.emotion_model,
                                         self.model.graph.emotions, span, self.sample_rate)
                self._auto_choice = choice.target
            except DataError as exc:
                self.stats.warnings[f"emotion auto: {exc}"[:80]] += 1
            self._auto_at = self.heard_s
        return self._auto_choice

    def _drop_old(self) -> None:
        """Forget audio no window or classification will hear again."""
        keep_from = int((self._sent / self.fps - self.context_s - 0.1) * self.sample_rate)
        if self._auto:
            keep_from = min(keep_from, self._heard - int(AUTO_SPAN_S * self.sample_rate))
        track_from = (self._track.settled / FRAME_RATE - self._track.context_s) - 0.02
        keep_from = min(keep_from, int(track_from * self.sample_rate))
        rows_from = int((self._sent / self.fps - self.context_s - 0.1) * FRAME_RATE)
        if self._transcript is not None:  # its path is extended from its fixed frames
            rows_from = min(rows_from, self._transcript.fixed)
            self._transcript.forget(rows_from)
        self._track.forget(rows_from)
        cut = keep_from - self._buffer_start
        if cut > 0:
            self._buffer = self._buffer[cut:]
            self._buffer_start += cut


@contextmanager
def capped_threads(threads: int | None):
    """At most ``threads`` threads for numba's parallel work on this thread (the DTW's
    pool takes that many) and for BLAS, within the block; None: no cap."""
    if threads is None:
        yield
        return
    import numba

    from animegraph.baselines.predicting import threadpools

    before = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        with threadpools().limit(limits=threads, user_api="blas"):
            yield
    finally:
        numba.set_num_threads(before)


def join(parts: list[Frames], empty: Frames) -> Frames:
    """Consecutive :class:`Frames` as one (``empty`` if there are none)."""
    parts = [p for p in parts if len(p)]
    if not parts:
        return empty
    return Frames(parts[0].first, np.concatenate([p.motion for p in parts]), parts[0].fps,
                  parts[-1].heard_s)


def check_rate(sample_rate) -> int:
    """``sample_rate`` if an int in [:data:`MIN_RATE`, :data:`MAX_RATE`] Hz, else
    ParameterError."""
    if (isinstance(sample_rate, bool) or not isinstance(sample_rate, int | np.integer)
            or not MIN_RATE <= int(sample_rate) <= MAX_RATE):
        raise ParameterError(f"sample rate {sample_rate!r} Hz is not supported: live "
                             f"speech must be {MIN_RATE}-{MAX_RATE} Hz")
    return int(sample_rate)


def as_mono_float(samples) -> np.ndarray:
    """Samples as float32 in [-1, 1], shape (n,): integer PCM scaled by its full scale;
    NaN or infinite samples refused (ParameterError)."""
    from ingest.speech.inputs import mono_samples

    return mono_samples(np.asarray(samples), np.float32, "live audio")


def default_guide_share(model) -> float:
    """The guide's share of each live window's motion when none is given, for ``model``.

    :data:`LIVE_GUIDE_SHARE` (calibrated on one speaker) for a database of one recording
    session; offline's :data:`animegraph.synthesis.guide.GUIDE_BLEND` (0.5, never tuned)
    where offline recentres each anime on its recording
    (:func:`animegraph.synthesis.recentres`: the database holds several sessions, i.e.
    speakers or corpus folders). mu-mlp hears the speaker and guides poorly across
    speakers: there 0.65 cost 0.013 mouth R against 0.5 (talkingface across speakers),
    and the calibration never held several. Sessions, not speakers, decide, because a
    database cannot tell two folders of one unnamed actor from two actors, and a wrong
    guess costs less this way: on one actress (FACEGOOD, 120 ms) 0.65 gained 0.002 over
    0.5 (docs/results/live.md, "The guide's share, live").

    Parameters
    ----------
    model : animegraph.synthesis.Model
        The motion database.

    Returns
    -------
    float
        The share, in [0, 1].
    """
    from animegraph.synthesis import recentres
    from animegraph.synthesis.guide import GUIDE_BLEND

    return GUIDE_BLEND if recentres(model) else LIVE_GUIDE_SHARE


def rest_pose(model) -> np.ndarray:
    """The database's rest pose in its channels, shape (n_channels,): the mean frame of
    its silence animes (of all animes if it has none)."""
    from animegraph.search.graph import PHONE_INDEX

    graph = model.graph
    nodes = graph.by_phone[PHONE_INDEX["SIL"]]
    if len(nodes):
        rows = np.concatenate([np.arange(graph.motion_offsets[k], graph.motion_offsets[k + 1])
                               for k in nodes])
        ics = graph.motion_values[rows].astype(np.float64).mean(axis=0)
    else:
        ics = graph.motion_values.astype(np.float64).mean(axis=0)
    return model.to_channels(ics[None])[0]


def stored_guide(db_root):
    """The offline audio-only default's guide as stored with the database (the models of
    :data:`animegraph.synthesis.path.AUDIO_ONLY_GUIDE`, restored without scikit-learn),
    without fitting any: a tuple, one model, or None; and the names missing."""
    from animegraph.baselines.stored import load_forward
    from animegraph.synthesis.path import AUDIO_ONLY_GUIDE

    names = (AUDIO_ONLY_GUIDE or "").split("+")
    found = {n: load_forward(db_root, n) for n in names if n}
    got = tuple(m for m in found.values() if m is not None)
    missing = tuple(n for n, m in found.items() if m is None)
    return (None if not got else got[0] if len(got) == 1 else got), missing
