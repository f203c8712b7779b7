"""``animegraph demo``: the whole pipeline, as far as it exists, on the embedded default data.

1. The default synthetic corpus is generated into the user's cache folder the first
   time, and ingested into the default motion database beside it (a later run reuses
   both).
2. A sentence that is not in the corpus is spoken in the chosen emotion and in
   neutral, with exact phone timing; its reference facial motion is made by the same
   face model as the corpus. These are the input and the ground truth that the later
   stages are measured against.
3. Facial motion for the sentence is synthesized from the database as ``synth`` does
   with known phones (:func:`animegraph.synthesis.path.synthesis_path`: the Anime Graph
   search, then each phone the mean of its 20 best animes ranked by phonetic context),
   with time-warping, blending and smoothing, from its speech and phone timing, in the
   chosen emotion.
4. The outputs and a PNG plot (reference and synthesized motion) are written to the
   output folder, and the synthesized motion is rendered on the face mesh with the
   speech as an MP4 (Cao et al. §7).
5. Meanwhile, from step 3 on, the guides a synthesis from speech alone needs are fitted
   on the database in a process beside this one (:class:`animegraph.apps.prepare.GuideFit`,
   as ``ingest`` fits them after it writes), so that the user's first ``synth`` of a
   recording finds them stored; :meth:`DemoResult.finish` waits for it.
"""

from __future__ import annotations

import json
import os
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from animegraph.apps.cache import default_corpus_dir, default_db_dir
from animegraph.apps.plots import plot_clips
from db.errors import ParameterError
from db.store import Database, is_database
from ingest.corpus.emotions import EMOTIONS, style
from ingest.corpus.synthetic import (
    ClipSpec,
    CorpusConfig,
    CorpusSummary,
    generate_corpus,
    plan_corpus,
    synthesize_clip,
    write_clip,
)

#: Not among the corpus' sentences (a test checks), so the demo is a held-out input.
DEMO_SENTENCE = "Would you like to hear how a brave robot learned to whistle a tune?"


@dataclass
class DemoResult:
    """What the demo made."""

    corpus: Path
    corpus_created: bool
    corpus_clips: int
    text: str
    emotion: str
    db: Path | None = None
    db_created: bool = False
    db_summary: str = ""
    candidates: list[tuple[str, int, int]] = field(default_factory=list)
    synthesis: str = ""
    outputs: list[Path] = field(default_factory=list)
    #: The guides' fit still running beside the demo (None: nothing to fit, or not asked).
    guides: object | None = None

    def finish(self, say: Callable[[str], object] | None = None) -> bool:
        """Wait for the guides' fit, if one runs; True unless it failed."""
        guides, self.guides = self.guides, None
        return True if guides is None else guides.wait(say or (lambda _line: None))

    def report(self) -> list[str]:
        """Lines to show the user."""
        state = "generated" if self.corpus_created else "reused"
        db_state = "built" if self.db_created else "reused"
        phones = [c for c in self.candidates if c[0] != "SIL"]
        fewest = min(phones, key=lambda c: c[2]) if phones else None
        missing = [c[0] for c in phones if c[1] == 0]
        lines = [
            f"corpus: {self.corpus} ({state}, {self.corpus_clips} clips)",
            f"database: {self.db} ({db_state}; {self.db_summary})",
            f"held-out sentence ({self.emotion}): {self.text}",
            f"search nodes: {len(self.candidates)} phones ({len(phones)} besides silence); "
            + (f"no anime in the database for {', '.join(sorted(set(missing)))}" if missing
               else "every one has matching animes in the database")
            + (f" (fewest in {self.emotion}: {fewest[0]}, {fewest[2]})" if fewest else ""),
            f"synthesized: {self.synthesis}",
            "outputs:",
            *[f"  {p}" for p in self.outputs],
            "demo_<emotion>.c3d is the reference motion from the corpus' face model "
            "(its rig controls in .controls.csv, its settings in .json);",
            "demo_<emotion>_synthesized.c3d is what the Anime Graph made from the speech;",
            "demo_<emotion>_synthesized.mp4 shows it on the face mesh, with the speech.",
        ]
        return lines


def ensure_default_corpus(
    *, workers: int | None = None, progress: Callable[..., Callable] | None = None,
    say: Callable[[str], object] | None = None,
) -> tuple[Path, bool, int]:
    """Generate the default corpus in the cache folder unless it is there already.

    Returns
    -------
    (path, created, n_clips)
    """
    path = default_corpus_dir()
    meta = path / "corpus.json"
    if meta.exists():
        return path, False, int(json.loads(meta.read_text())["n_clips"])
    config = CorpusConfig()
    n = len(plan_corpus(config))
    summary: CorpusSummary = generate_corpus(
        path, config, workers=workers, force=True,
        progress=progress(n, "generating the corpus") if progress else None, say=say,
    )
    return path, True, summary.n_clips


def run_demo(
    out: Path,
    *,
    emotion: str = "happy",
    text: str | None = None,
    workers: int | None = None,
    progress: Callable[..., Callable] | None = None,
    say: Callable[[str], object] | None = None,
    prepare: bool = True,
) -> DemoResult:
    """Run the demo; see the module docstring. With ``prepare`` the caller waits for the
    guides' fit with :meth:`DemoResult.finish` once it has shown the result.

    Parameters
    ----------
    out : Path
        Output folder (created; files in it with the demo's names are replaced).
    emotion : str
        Emotion of the held-out sentence, one of the five.
    text : str, optional
        The sentence (default :data:`DEMO_SENTENCE`).
    workers : int, optional
        Processes for generating the corpus.
    progress : callable, optional
        ``progress(total, step)`` returns a wrapper for an iterable of finished clips,
        labelled with the step.
    say : callable, optional
        Receives a line of news before each long step.
    prepare : bool
        Fit the database's missing default guides beside the demo (step 5).
    """
    style(emotion)  # validates the name before any work
    text = DEMO_SENTENCE if text is None else text
    if not text.strip():
        raise ParameterError("--text must not be empty")
    say = say or (lambda _line: None)
    if not (default_corpus_dir() / "corpus.json").exists():
        say(f"generating the default corpus in {default_corpus_dir()} (once) ...")
    corpus, created, n_clips = ensure_default_corpus(workers=workers, progress=progress,
                                                     say=say)
    db_path, db_created = ensure_default_db(corpus, workers=workers, progress=progress,
                                            say=say)
    from animegraph.apps.prepare import GuideFit

    guides = GuideFit.start(db_path, say) if prepare else None
    if guides is not None:
        say("fitting the guides of synth from speech alone beside the demo (stored with "
            "the database; lines 'guides: ...') ...")
    try:
        result = _synthesize_demo(db_path, db_created, corpus, created, n_clips, out,
                                  emotion, text, say)
    except BaseException:
        if guides is not None:
            guides.stop()
        raise
    result.guides = guides
    return result


def _synthesize_demo(db_path: Path, db_created: bool, corpus: Path, created: bool,
                     n_clips: int, out: Path, emotion: str, text: str, say) -> DemoResult:
    """Steps 2-4 of the module docstring on the built database."""
    db = Database.open(db_path)

    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ParameterError(f"cannot create --out {out}: {exc.strerror}") from exc
    config = CorpusConfig()
    clips = []
    for emo in dict.fromkeys([emotion, "neutral"]):
        spec = ClipSpec(clip_id=f"demo_{emo}", sentence_id="demo", text=text, emotion=emo,
                        variation=1, speaker=config.speaker, seed=EMOTIONS.index(emo) + 1)
        clips.append(synthesize_clip(spec, config))
    m = db.manifest
    result = DemoResult(
        corpus=corpus, corpus_created=created, corpus_clips=n_clips, text=text,
        emotion=emotion, db=db_path, db_created=db_created,
        db_summary=f"{m['n_clips']} clips, {m['n_animes']} animes, {m['n_pcs']} components",
        candidates=_candidates(db, clips[0], emotion),
    )
    for clip in clips:
        write_clip(clip, out)
        stem = out / clip.spec.clip_id
        result.outputs += [stem.with_suffix(".wav"), stem.with_suffix(".c3d"),
                           Path(f"{stem}.phones.csv"), Path(f"{stem}.controls.csv"),
                           stem.with_suffix(".json")]
    from animegraph.search.kernels import compile_notice
    from animegraph.synthesis import Model, synthesize, write_motion
    from animegraph.synthesis.path import synthesis_path
    from ingest.formats.phones_csv import Segment

    say("synthesizing the held-out sentence from the database ...")
    notice = compile_notice()
    if notice:
        say(notice)
    model = Model.load(db_path)
    first = clips[0]
    labels = [Segment(p.phone, p.start, p.end) for p in first.utterance.phones]
    k_best, path = synthesis_path("the sentence's phone labels", known_phones=True)
    synth = synthesize(model, first.utterance.audio, first.utterance.sample_rate,
                       labels=labels, emotion=emotion, k_best=k_best)
    synth_path = write_motion(synth, model, out / f"demo_{emotion}_synthesized.c3d")
    result.outputs.append(synth_path)
    result.synthesis = (f"{len(synth.phones)} phones, {synth.result.n_jumps} jump matches, "
                        f"{synth.timings['total_s']:.2f} s for "
                        f"{first.utterance.duration:.1f} s of speech; path: {path}")
    markers = synth.motion.reshape(len(synth.motion), -1, 3)
    png = plot_clips(clips, out / "demo.png",
                     title=f"held-out sentence, {emotion} vs neutral: {text}",
                     synthesized={f"synthesized ({emotion})": (markers, synth.fps)})
    result.outputs.append(png)
    result.outputs.append(_render_video(synth, model, out, emotion, say))
    return result


def _render_video(synth, model, out: Path, emotion: str, say) -> Path:
    """The synthesized sentence on the face mesh, with its speech: an MP4 (§7)."""
    from animegraph.face.render import deformer_for, render_motion
    from animegraph.motion.files import Motion

    say("rendering the synthesized motion on the face mesh ...")
    motion = Motion(values=synth.motion, names=model.names, fps=synth.fps)
    path = out / f"demo_{emotion}_synthesized.mp4"
    return render_motion(motion, path, deformer=deformer_for(model.names),
                         audio=out / f"demo_{emotion}.wav", phones=synth.explain)


def ensure_default_db(
    corpus: Path, *, workers: int | None = None,
    progress: Callable[..., Callable] | None = None,
    say: Callable[[str], object] | None = None,
) -> tuple[Path, bool]:
    """Ingest the default corpus into the default database unless it is there already and
    its emotion model is this version's (:func:`ingest.emotion.model.stored_model_current`)."""
    from ingest.emotion.model import stored_model_current
    from ingest.pipeline import ingest

    path = default_db_dir()
    manifest = Database.open(path).manifest if is_database(path) else None
    if manifest is not None and stored_model_current(manifest):
        return path, False
    # A database from before emotion models, or before this version's emotion classifier:
    # brought up to date by ingest (which learns the model again from the stored clips).
    if say:
        say(f"building the default database in {path} (once) ..." if manifest is None else
            f"updating the default database in {path}: its emotion model predates this "
            "version's ...")
    ingest([corpus], path, workers=workers or os.cpu_count() or 1,
           progress=(lambda total: progress(total, "ingest: reading clips")) if progress
           else None, say=say)
    return path, True


def _candidates(db: Database, clip, emotion: str) -> list[tuple[str, int, int]]:
    """(phone, animes with that phoneme, of them in ``emotion``) for each input phone."""
    table = db.table("animes", columns=["phoneme", "emotion"]).to_pylist()
    total = Counter(r["phoneme"] for r in table)
    same = Counter(r["phoneme"] for r in table if r["emotion"] == emotion)
    return [(p.phone, total[p.phone], same[p.phone]) for p in clip.utterance.phones]
