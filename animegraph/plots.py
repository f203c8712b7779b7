"""Pictures an animator checks: speech, phones and facial measures over time."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ingest.corpus import face

#: Distances between markers that read as facial actions whatever the head does.
MEASURES: tuple[tuple[str, str, str], ...] = (
    ("mouth opening (mm)", "ulip_in_c", "llip_in_c"),
    ("lip corner to eye (mm)", "lip_corner_r", "eye_out_r"),
    ("brow to eye (mm)", "brow_r1", "eye_in_r"),
)


def plot_clips(clips: Sequence, path: Path, *, title: str = "",
               synthesized: dict[str, tuple[np.ndarray, float]] | None = None) -> Path:
    """Plot speech, phones and facial measures of clips of one sentence.

    Parameters
    ----------
    clips : sequence of ingest.corpus.synthetic.Clip
        The first is drawn with its waveform and phone labels; all are overlaid in the
        measure panels, labelled by emotion.
    path : Path
        PNG file to write.
    synthesized : dict of str to (markers, fps), optional
        Synthesized marker motion (n_frames, n_markers, 3) to overlay, dashed, by label.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = 2 + len(MEASURES)
    fig, axes = plt.subplots(rows, 1, figsize=(11, 2.0 * rows), sharex=True)
    first = clips[0]
    utt = first.utterance
    t_audio = np.arange(len(utt.audio)) / utt.sample_rate
    axes[0].plot(t_audio, utt.audio, lw=0.4, color="0.3")
    axes[0].set_ylabel(f"speech\n({first.spec.emotion})")
    for k, seg in enumerate(utt.phones):
        if seg.phone == "SIL":
            continue
        mid = 0.5 * (seg.start + seg.end)
        axes[0].axvline(seg.start, color="0.85", lw=0.5)
        axes[0].text(mid, 0.9 if k % 2 else 0.7, seg.phone, ha="center", fontsize=6,
                     transform=axes[0].get_xaxis_transform())
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, clip in enumerate(clips):
        t = np.arange(len(clip.markers)) / clip.fps
        for ax, (name, a, b) in zip(axes[1:], MEASURES, strict=False):
            ax.plot(t, face.marker_distance(clip.markers, a, b), lw=1,
                    color=colors[i % len(colors)], label=clip.spec.emotion)
            ax.set_ylabel(name)
        pitch = clip.controls[:, face.CONTROLS.index("head_pitch")]
        axes[-1].plot(t, pitch, lw=1, color=colors[i % len(colors)])
    for k, (label, (markers, fps)) in enumerate((synthesized or {}).items()):
        t = np.arange(len(markers)) / fps
        for ax, (_, a, b) in zip(axes[1:], MEASURES, strict=False):
            ax.plot(t, face.marker_distance(markers, a, b), "--", lw=1.2,
                    color=colors[(len(clips) + k) % len(colors)], label=label)
    axes[-1].set_ylabel("head pitch (deg)")
    axes[-1].set_xlabel("time (s)")
    axes[1].legend(loc="upper right", fontsize=7, ncol=len(clips) + len(synthesized or {}))
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_heldout(model, clip, path: Path, *, methods=("exact", "window3", "random")) -> Path:
    """Mouth opening of a held-out clip: recorded against synthesized by ``methods``.

    Thin vertical lines mark the exact search's jump matches; phone labels run along the
    bottom.
    """
    from animegraph import evaluate
    from animegraph.synth import render_nodes

    phones, emotion, cands, audio_cost = evaluate.heldout_query(model, clip)
    predictions, styles, marks = {}, {}, []
    for method in methods:
        nodes, _ = evaluate.method_nodes(model, cands, audio_cost, method, emotion=emotion,
                                         rng=np.random.default_rng(0))
        ics, joins = render_nodes(model, phones, nodes, emotion=emotion)
        predictions[method] = model.decomposer.inverse_transform(ics)
        styles[method] = ":" if method in ("random", "first") else "-"
        if method == "exact":
            marks = [phones[j["index"] + 1].start for j in joins]
    return _plot_mouth(clip, predictions, model.names, model.kind, path, fps=model.graph.fps,
                       phones=phones, styles=styles, marks=marks,
                       title=f"held-out {clip.clip_id} ({clip.emotion}): recorded vs "
                             "synthesized")


def plot_systems(clip, predictions: dict[str, np.ndarray], names: Sequence[str], kind: str,
                 path: Path, *, seconds: float | None = None) -> Path:
    """Mouth opening of a held-out clip: recorded against every system's synthesis.

    Parameters
    ----------
    clip : ingest.prepare.PreparedClip
        The held-out clip (its motion is the ground truth).
    predictions : dict of str to np.ndarray, shape (n_frames, n_channels)
        Motion of each system (e.g. ``exact`` for the Anime Graph, ``mu-mlp`` ...), in the
        database's channels at the clip's frame rate.
    seconds : float, optional
        Show only the first ``seconds`` of the clip (a long real clip is unreadable whole).
    """
    span = None if seconds is None or seconds >= clip.duration else (0.0, float(seconds))
    return _plot_mouth(clip, predictions, names, kind, path, fps=clip.fps, phones=clip.phones,
                       span=span,
                       title=f"held-out {clip.clip_id} ({clip.emotion}): recorded vs every "
                             "system" + (f", first {seconds:g} s" if span else ""))


def _plot_mouth(clip, predictions: dict[str, np.ndarray], names: Sequence[str], kind: str,
                path: Path, *, fps: float, phones, title: str, styles=None,
                marks: Sequence[float] = (), span: tuple[float, float] | None = None) -> Path:
    """The recorded mouth opening (black) against each prediction, phones along the
    bottom, thin lines at ``marks`` (s), only the time ``span`` (s) if given; written to
    ``path`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from animegraph import evaluate

    fig, ax = plt.subplots(figsize=(11, 3.5))
    truth = clip.motion.astype(np.float64)
    ax.plot(np.arange(len(truth)) / fps, evaluate.mouth_opening(truth, names, kind), "k",
            lw=2, label="recorded")
    for k, (label, pred) in enumerate(predictions.items()):
        ax.plot(np.arange(len(pred)) / fps, evaluate.mouth_opening(pred, names, kind),
                f"C{k}" + (styles or {}).get(label, "-"), lw=1, label=label)
    for t in marks:
        ax.axvline(t, color="C0", lw=0.5, alpha=0.4)
    for p in phones:
        if p.phone != "SIL" and (span is None or span[0] <= p.start < span[1]):
            ax.text((p.start + p.end) / 2, 0.02, p.phone, fontsize=6, ha="center",
                    transform=ax.get_xaxis_transform())
    if span is not None:
        ax.set_xlim(*span)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("mouth opening")
    ax.set_title(title)
    ax.legend(fontsize=7, ncol=len(predictions) + 1)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
