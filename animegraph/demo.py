"""``animegraph demo``: the whole pipeline, as far as it exists, on the embedded default data.

1. The default synthetic corpus is generated into the user's cache folder the first
   time (a later run reuses it).
2. A sentence that is not in the corpus is spoken in the chosen emotion and in
   neutral, with exact phone timing; its reference facial motion is made by the same
   face model as the corpus. These are the input and the ground truth that the later
   stages (database, Anime Graph search, synthesis) are measured against.
3. The outputs and a PNG plot are written to the output folder.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from animegraph.cache import default_corpus_dir
from animegraph.plots import plot_clips
from db.errors import ParameterError
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
    outputs: list[Path] = field(default_factory=list)

    def report(self) -> list[str]:
        """Lines to show the user."""
        state = "generated" if self.corpus_created else "reused"
        lines = [
            f"corpus: {self.corpus} ({state}, {self.corpus_clips} clips)",
            f"held-out sentence ({self.emotion}): {self.text}",
            "outputs:",
            *[f"  {p}" for p in self.outputs],
            "The database, Anime Graph search and synthesis stages are not built yet: the",
            "motion written here is the reference (ground truth) from the corpus' face model.",
        ]
        return lines


def ensure_default_corpus(
    *, workers: int | None = None, progress: Callable[[int], Callable] | None = None,
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
        path, config, workers=workers, force=True, progress=progress(n) if progress else None,
    )
    return path, True, summary.n_clips


def run_demo(
    out: Path,
    *,
    emotion: str = "happy",
    text: str | None = None,
    workers: int | None = None,
    progress: Callable[[int], Callable] | None = None,
    say: Callable[[str], object] | None = None,
) -> DemoResult:
    """Run the demo; see the module docstring.

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
        ``progress(total)`` returns a wrapper for an iterable of finished clips.
    say : callable, optional
        Receives a line of news before each long step.
    """
    style(emotion)  # validates the name before any work
    text = DEMO_SENTENCE if text is None else text
    if not text.strip():
        raise ParameterError("--text must not be empty")
    say = say or (lambda _line: None)
    if not (default_corpus_dir() / "corpus.json").exists():
        say(f"generating the default corpus in {default_corpus_dir()} (once) ...")
    corpus, created, n_clips = ensure_default_corpus(workers=workers, progress=progress)

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
    result = DemoResult(corpus=corpus, corpus_created=created, corpus_clips=n_clips,
                        text=text, emotion=emotion)
    for clip in clips:
        write_clip(clip, out)
        stem = out / clip.spec.clip_id
        result.outputs += [stem.with_suffix(".wav"), stem.with_suffix(".c3d"),
                           Path(f"{stem}.phones.csv")]
    png = plot_clips(clips, out / "demo.png",
                     title=f"held-out sentence, {emotion} vs neutral: {text}")
    result.outputs.append(png)
    return result
