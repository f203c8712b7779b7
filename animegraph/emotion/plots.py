"""Pictures of the emotion model: the component split (§5.1.3) and a held-out mapping
(the paper's Fig. 7)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ingest.emotion.components import (
    EMOTION_MIN_DIFFERENCE,
    EMOTION_MIN_RATIO,
    SPEECH_MIN_SHARE,
    ComponentSplit,
)

_COLOURS = {"speech": "tab:blue", "emotion": "tab:red", "other": "tab:gray"}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_split(split: ComponentSplit, path: Path, *, truth: Sequence[dict] | None = None,
               title: str = "") -> Path:
    """Bar charts of each component's speech score (Eq. 9) and emotion score, coloured by
    label, with the thresholds; ``truth`` (from :func:`component_truth`) adds the
    generator's control each component follows."""
    plt = _pyplot()
    n = len(split.labels)
    k = np.arange(n)
    colours = [_COLOURS[lab] for lab in split.labels]
    fig, axes = plt.subplots(2, 1, figsize=(max(6.0, 0.8 * n + 2), 6.5), sharex=True)
    axes[0].bar(k, split.speech_score, color=colours)
    axes[0].axhline(SPEECH_MIN_SHARE, color="k", ls=":", lw=1)
    axes[0].set_ylabel("speech score\n(mouth motion share, Eq. 9)")
    score = np.nan_to_num(split.emotion_score)
    axes[1].bar(k - 0.2, score, width=0.4, color=colours, label="across emotions")
    axes[1].bar(k + 0.2, np.nan_to_num(split.emotion_baseline), width=0.4, color="none",
                edgecolor="k", label="same emotion (baseline)")
    axes[1].axhline(EMOTION_MIN_DIFFERENCE, color="k", ls=":", lw=1)
    axes[1].set_ylabel("emotion score\n(difference / variation)")
    axes[1].set_yscale("symlog", linthresh=1.0)
    axes[1].legend(loc="upper right", fontsize=8)
    names = []
    for i in range(n):
        label = f"{i}\n{split.labels[i]}"
        if truth is not None:
            label += f"\n{truth[i]['top_control']}\n(truth: {truth[i]['truth']})"
        names.append(label)
    axes[1].set_xticks(k, names, fontsize=7)
    fig.suptitle(title or f"speech / emotion components (emotion: score >= "
                 f"{EMOTION_MIN_DIFFERENCE:g} and >= {EMOTION_MIN_RATIO:g} x baseline)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_mapping(held, names: Sequence[str], path: Path, *, rms: dict | None = None,
                 n_snapshots: int = 5) -> Path:
    """The paper's Fig. 7: the source motion (row 1), its mapping into the target emotion
    (row 2) and the recorded target motion (row 3) at ``n_snapshots`` frames (front view of
    the markers), plus the emotion components over time.

    Parameters
    ----------
    held : animegraph.emotion.evaluate.HeldOut
    names : sequence of str
        Channel names (x/y/z triples).
    rms : dict, optional
        Unit-cube RMS of ``mapped``, ``none`` and ``offset``, for the titles.
    """
    plt = _pyplot()
    frames = np.linspace(0, len(held.source) - 1, n_snapshots + 2)[1:-1].astype(int)
    rows = [(f"{held.src} (recorded, {held.clip_src})", held.source),
            (f"mapped {held.src} -> {held.dst}", held.mapped),
            (f"{held.dst} (recorded, {held.clip_dst}, aligned)", held.recorded)]
    fig = plt.figure(figsize=(2.2 * n_snapshots, 10))
    grid = fig.add_gridspec(4, n_snapshots, height_ratios=[1, 1, 1, 1.1])
    pts = [m.reshape(len(m), -1, 3) for _, m in rows]
    lo = np.min([p[..., :2].min(axis=(0, 1)) for p in pts], axis=0)
    hi = np.max([p[..., :2].max(axis=(0, 1)) for p in pts], axis=0)
    for r, ((label, _), p) in enumerate(zip(rows, pts, strict=True)):
        for c, f in enumerate(frames):
            ax = fig.add_subplot(grid[r, c])
            ax.scatter(p[f, :, 0], p[f, :, 1], s=4, c="k" if r != 1 else "tab:red")
            ax.set_xlim(lo[0], hi[0])
            ax.set_ylim(lo[1], hi[1])
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            if c == 0:
                ax.set_ylabel(label, fontsize=7)
            if r == 0:
                ax.set_title(f"frame {f}", fontsize=8)
    ax = fig.add_subplot(grid[3, :])
    t = np.arange(len(held.e_source))
    for k in range(held.e_source.shape[1]):
        colour = f"C{k}"
        ax.plot(t, held.e_source[:, k], color=colour, ls=":", lw=1)
        ax.plot(t, held.e_mapped[:, k], color=colour, lw=1.5)
        ax.plot(t, held.e_recorded[:, k], color=colour, ls="--", lw=1)
    ax.set_xlabel("frame (source timing)")
    ax.set_ylabel("emotion components")
    ax.set_title("dotted: source, solid: mapped, dashed: recorded target (aligned)",
                 fontsize=8)
    head = f"held-out sentence {held.sentence}: {held.src} -> {held.dst}"
    if rms:
        head += (f"; unit-cube RMS mapped {rms['mapped']:.4f}, no mapping {rms['none']:.4f}, "
                 f"mean offset {rms['offset']:.4f} (paper: 0.0117)")
    fig.suptitle(head, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


def plot_timeline(windows: Sequence, path: Path, *, title: str = "") -> Path:
    """Each emotion's probability over time, one line per emotion at the windows' centres
    (:class:`ingest.emotion.timeline.Window`), the leading emotion shaded below; windows
    not classified (silence, not speech) are gaps."""
    plt = _pyplot()
    speech = [w for w in windows if w.probabilities is not None]
    names = sorted({n for w in speech for n in w.probabilities})
    fig, ax = plt.subplots(figsize=(10, 3.8))
    centres = np.array([(w.start + w.end) / 2 for w in windows])
    colours = plt.get_cmap("tab10")
    for k, name in enumerate(names):
        p = np.array([np.nan if w.probabilities is None else w.probabilities.get(name, 0.0)
                      for w in windows])
        ax.plot(centres, p, marker=".", color=colours(k % 10), label=name)
    for w in speech:
        top = next(iter(w.probabilities))
        ax.axvspan(w.start, w.end, ymin=0, ymax=0.04, color=colours(names.index(top) % 10),
                   alpha=0.6, lw=0)
    ax.set_xlim(0, max((w.end for w in windows), default=1.0))
    ax.set_ylim(0, 1)
    ax.set_xlabel("time (s), each point a window's centre")
    ax.set_ylabel("probability")
    ax.set_title(title or "emotion over time")
    ax.legend(loc="upper right", fontsize="small", ncols=min(len(names), 4) or 1)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
