"""Ready before first use: what a database's first ``synth`` would otherwise do itself.

A fresh database lacks two things its first audio-only ``synth`` needs: the default
guides (:data:`animegraph.synthesis.path.AUDIO_ONLY_GUIDE`, fitted on the database and
stored with its version) and, in a fresh environment, the search's numba kernels
compiled and cached on disk (:mod:`animegraph.search.kernels`). Fitted inside that
``synth`` they cost minutes (GRID s1, before the fits were made fast: mu-mlp 121 s,
ppg-ridge 277 s, the kernels about a minute on two cores; now 18.0 and 10.3 CPU-s,
docs/results/speed.md, "The guides' fit on GRID s1"). ``animegraph ingest`` does both
once the database is written, and ``animegraph warmup`` does them on demand; each step
is said with its time. ``animegraph demo`` fits the guides in a process beside its own
synthesis (:class:`GuideFit`), which compiles the kernels of synth's default path.

The guides are fitted with hama's outputs kept in the cache folder
(:func:`ingest.speech.ctc.kept_on_disk`), so the refit after the next ingest (a new
version, every clip again) hears only the clips it added: on the demo's database
(16.5 min of speech, 2 busy cores) ppg-ridge took 76.6 CPU-s the first time and 13.3
CPU-s again; mu-mlp about 10 CPU-s each time.

Data flows ``ingest`` -> ``db`` -> ``animegraph``: ingest does not know the guides, so
the command line's ``ingest`` calls :func:`prepare` after :func:`ingest.pipeline.ingest`
returns, holding the database's writer lock throughout, so the models are fitted on
the version they are stored under.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Callable
from pathlib import Path

from db.errors import AnimeGraphError

__all__ = ["GuideFit", "compile_kernels", "fit_estimate", "fit_guides", "prepare",
           "unfitted_note", "warm_kernels"]

#: The sentence whose synthesis compiles the kernels (short: its phones cost nothing).
WARM_SENTENCE = "Good morning, class."
#: CPU seconds a default guide's fit takes per minute of the database's speech, at most:
#: mu-mlp 23.5 CPU-s on GRID s1 (39.7 min, 1,411 channels); ppg-ridge 73 CPU-s on the
#: demo's database (16.5 min of speech, no stored posteriorgrams, so hama hears every
#: clip, on one thread a core) (``scripts/bench_guide_fit.py``).
FIT_CPU_S_PER_MIN = {"mu-mlp": 0.6, "ppg-ridge": 4.5}
#: ppg-ridge's CPU seconds per minute of speech whose posteriorgram the database stores
#: (hama does not hear it again): GRID s1's 10.3 CPU-s for 39.7 min, docs/results/speed.md
#: "The guides' fit on GRID s1".
PPG_RIDGE_STORED_CPU_S_PER_MIN = 0.3
#: The fits that spread over the cores (ppg-ridge's hama, one clip a thread).
_THREADED = frozenset({"ppg-ridge"})


def fit_estimate(db: Path, name: str) -> str:
    """About how long fitting the guide ``name`` on ``db`` takes here, for a message
    (``"about 40 s"``; empty if unknown)."""
    from db.store import Database
    from db.system import usable_cpus

    try:
        database = Database.open(db)
        minutes = float(database.manifest["duration_s"]) / 60
        heard = _minutes_without_posteriors(database) if name == "ppg-ridge" else minutes
    except (AnimeGraphError, OSError, KeyError, TypeError, ValueError):
        return ""
    seconds = FIT_CPU_S_PER_MIN.get(name, 0.0) * min(heard, minutes)
    if name in _THREADED:
        seconds /= max(1, usable_cpus())
    if name == "ppg-ridge":  # the ridge itself, on one core, over every clip
        seconds += PPG_RIDGE_STORED_CPU_S_PER_MIN * max(minutes - heard, 0.0)
    if seconds <= 0:
        return ""
    return (f"about {max(seconds, 1):.0f} s" if seconds < 90
            else f"about {seconds / 60:.0f} min") + " on a quiet machine"


def _minutes_without_posteriors(database) -> float:
    """Minutes of the database's speech whose posteriorgram it does not store: hama hears
    them again when ppg-ridge is fitted (two small columns of the clips table)."""
    clips = database.table("clips", columns=["duration", "posterior_frames"]).to_pydict()
    return sum(float(d or 0.0) for d, n in zip(clips["duration"], clips["posterior_frames"],
                                               strict=True) if not n) / 60


def _quiet(line: str) -> None:
    pass


def fit_guides(db: Path, say: Callable[[str], object] = _quiet) -> dict[str, str]:
    """Fit and store every default guide the live version of ``db`` lacks.

    A guide that cannot be fitted (too little data, say) is kept as unfit with its
    reason (:func:`animegraph.baselines.stored.record_unfit`), as ``synth`` would, so
    that ``synth`` says why instead of trying again.

    Returns
    -------
    dict
        Guide name -> ``"stored"`` (there already), ``"fitted"`` or the reason it is not.
    """
    from animegraph.baselines.stored import load_forward, record_unfit, unfit_reason
    from animegraph.synthesis.path import AUDIO_ONLY_GUIDE

    done = {}
    data = None  # the database's clips, read once for every guide (GRID s1: 30 s a read)
    for name in (AUDIO_ONLY_GUIDE or "").split("+"):
        if not name:
            continue
        try:
            stored = load_forward(db, name) is not None
        except AnimeGraphError:  # unreadable or foreign: fitted again and replaced
            stored = False
        if stored:
            done[name] = "stored"
            continue
        reason = unfit_reason(db, name)
        if reason is not None:
            done[name] = reason
            continue
        from animegraph.baselines.base import fitted_model
        from animegraph.baselines.data import training_set
        from ingest.speech import ctc

        how_long = fit_estimate(db, name)
        say(f"fitting the {name} guide of audio-only synth ({how_long + '; ' if how_long else ''}"
            "stored with the database) ...")
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            # hama's outputs kept in the cache as ingest keeps them: the refit after the
            # next ingest (a new version) hears only the clips it added.
            with ctc.kept_on_disk():
                data = training_set(db) if data is None else data
                fitted_model(db, name, refit=True, data=data)
        except (AnimeGraphError, OSError) as exc:
            say(f"warning: no {name} guide ({exc})")
            record_unfit(db, name, str(exc))
            done[name] = str(exc)
            continue
        say(f"fitted {name} in {time.perf_counter() - t0:.1f} s "
            f"({time.process_time() - c0:.1f} s CPU)")
        done[name] = "fitted"
    return done


def unfitted_note(db: Path) -> str | None:
    """A line saying which default guides ``db`` lacks and how long the first audio-only
    ``synth`` will spend fitting them (None if none is missing): for commands that build
    a database without fitting them (``demo``, whose own sentence has its phones)."""
    from animegraph.baselines.stored import model_path, unfit_reason
    from animegraph.synthesis.path import AUDIO_ONLY_GUIDE

    missing = [name for name in (AUDIO_ONLY_GUIDE or "").split("+") if name
               and not model_path(db, name).is_file() and unfit_reason(db, name) is None]
    if not missing:
        return None
    times = ", ".join(f"{name} {fit_estimate(db, name) or 'unknown time'}" for name in missing)
    return (f"the first synth from speech alone on {db} fits its guides first ({times}); "
            f"'animegraph warmup --db {db}' does it now")


def compile_kernels(db: Path, say: Callable[[str], object] = _quiet) -> list[str]:
    """Compile and cache the search kernels ``synth`` runs, if any are not yet
    (:func:`warm_kernels`). Returns the kernels that were missing (empty: nothing done)."""
    from animegraph.search.kernels import COMPILE_NOTE, uncompiled_kernels

    missing = sorted(set(uncompiled_kernels("exact")) | set(uncompiled_kernels("paper")))
    if not missing:
        return []
    say(f"compiling the search kernels once ({len(missing)} to go, {COMPILE_NOTE}; cached "
        "for every later synth) ...")
    t0, c0 = time.perf_counter(), time.process_time()
    warm_kernels(db)
    say(f"compiled the search kernels in {time.perf_counter() - t0:.1f} s "
        f"({time.process_time() - c0:.1f} s CPU)")
    return missing


def warm_kernels(db: Path, methods: set[tuple[str, int | None]] | None = None, *,
                 align: bool = False) -> None:
    """Compile (and cache) the numba kernels synthesis runs, in this process.

    One short eSpeak NG sentence is synthesized against ``db`` with its phone labels: by
    each ``(method, window)`` of ``methods``, or by default along ``synth``'s default
    path (k-best), the paper's exact search and its original search; with ``align`` also
    from its transcript (forced alignment). A synthesis scores enough pairs for the
    audio cost's threaded path (it runs the same kernel as the serial one).
    """
    import numpy as np

    from animegraph.search.dtw import audio_costs_many
    from animegraph.search.shortlist import box_bounds
    from animegraph.synthesis import Model, synthesize
    from animegraph.synthesis.path import synthesis_path
    from ingest.formats.phones_csv import Segment
    from ingest.speech.espeak import Voice, speak

    model = Model.load(db)
    utt = speak(WARM_SENTENCE, Voice())
    labels = [Segment(p.phone, p.start, p.end) for p in utt.phones]
    if methods is None:
        k_best, _ = synthesis_path("labels", known_phones=True)  # synth's default path
        runs = [{"k_best": k_best}, {"method": "exact"}, {"method": "paper"}]
    else:
        runs = [{"method": m, "window": w} for m, w in sorted(methods, key=str)]
    # The warm-up's answers are thrown away: what its searches would warn a user of (the
    # paper's search stopping at its cap) is not this command's to say.
    search_log = logging.getLogger("animegraph.search")
    level = search_log.level
    search_log.setLevel(logging.ERROR)
    try:
        for options in runs:
            synthesize(model, utt.audio, utt.sample_rate, labels=labels, **options)
        if align:
            synthesize(model, utt.audio, utt.sample_rate, text=utt.text)
        # Two kernels a small database's synthesis never calls: the shortlist's bound (run
        # only where a phone has more candidates than the shortlist keeps) and the DTW's
        # scan of curves not checked at load (a mapped graph's). Left out, every later
        # command would announce their compilation. Compiled here with the types they run on.
        graph, n = model.graph, min(2, model.graph.n_nodes)
        nodes = [np.arange(n, dtype=np.int64)]
        box_bounds(graph, [graph.prosody_values[:1]], nodes)
        offsets = np.asarray(graph.prosody_offsets[:n + 1])
        curves = np.array(graph.prosody_values[:offsets[-1]])  # a copy: not marked checked
        audio_costs_many([curves[:1]], curves, offsets, nodes)
    finally:
        search_log.setLevel(level)


class GuideFit:
    """:func:`fit_guides` of a database in a process beside this one, under the database's
    writer lock: started with :meth:`start`, waited for with :meth:`wait`.

    ``animegraph demo`` fits the guides of speech alone while it synthesizes and renders
    its own sentence (which has its phones and needs none): mostly one core's work
    (the search kernels' first compilation, drawing the frames) beside the fit's, so the
    second core does the fitting; a synth after the demo then finds them stored. The
    fit's lines come back through a pipe and are said here, prefixed ``guides:``.
    """

    #: Seconds a child given a Ctrl-C has to stop (its writes are atomic) before it is
    #: killed.
    GRACE_S = 10.0

    def __init__(self, process, relay) -> None:
        self._process = process
        self._relay = relay

    @classmethod
    def start(cls, db: Path, say: Callable[[str], object] = _quiet) -> GuideFit | None:
        """The fit of ``db``'s missing default guides started in a spawned process, its
        lines passed to ``say``; None when none is missing (:func:`unfitted_note`)."""
        import multiprocessing
        import threading

        if unfitted_note(db) is None:
            return None
        context = multiprocessing.get_context("spawn")
        receive, send = context.Pipe(duplex=False)
        # Not a daemon: a fit may start processes of its own (a daemon may not), and a
        # caller that ends without waiting leaves it to finish what it stores.
        process = context.Process(target=_fit_guides_child, args=(str(db), send),
                                  name="animegraph-guides")
        process.start()
        send.close()  # the child's end: the relay's recv ends when the child's is closed

        def relay() -> None:
            with contextlib.suppress(EOFError, OSError):
                while True:
                    say(f"guides: {receive.recv_bytes().decode()}")
            receive.close()

        thread = threading.Thread(target=relay, name="animegraph-guides-relay", daemon=True)
        thread.start()
        return cls(process, thread)

    def wait(self, say: Callable[[str], object] = _quiet) -> bool:
        """Wait for the fit (saying so if it is still running); True if it ended well.
        A Ctrl-C meanwhile stops it (:meth:`stop`) and is raised."""
        if self._process.is_alive():
            say("waiting for the guides of synth from speech alone, fitted beside the "
                "demo ...")
        try:
            self._process.join()
        except BaseException:
            self.stop()
            raise
        self._relay.join()  # every line said before the caller goes on
        return self._process.exitcode == 0

    def stop(self) -> None:
        """End the fit: a Ctrl-C first (what it writes is atomic, the database stays as
        it was), killed after :attr:`GRACE_S`."""
        import os
        import signal

        if self._process.is_alive():
            with contextlib.suppress(OSError):
                os.kill(self._process.pid, signal.SIGINT)
            self._process.join(self.GRACE_S)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()


def _fit_guides_child(db: str, lines) -> None:
    """:class:`GuideFit`'s process: the fit under the writer lock, its lines sent back
    through the pipe ``lines`` as UTF-8 bytes."""
    import sys

    from db.lock import writer_lock

    def send(line: str) -> None:  # text as bytes: nothing is unpickled on the way back
        lines.send_bytes(str(line).encode())

    try:
        with writer_lock(db, wait=600.0, what="database"):
            fit_guides(Path(db), send)
    except KeyboardInterrupt:
        sys.exit(130)
    except (AnimeGraphError, OSError) as exc:
        send(f"not fitted: {exc}")
        sys.exit(1)
    finally:
        lines.close()


def prepare(db: Path, say: Callable[[str], object] = _quiet) -> None:
    """:func:`fit_guides`, then :func:`compile_kernels`: ``db`` ready for its first
    ``synth``."""
    fit_guides(db, say)
    compile_kernels(db, say)
