"""Pictures an animator checks: speech, phones and facial measures over time.

* :func:`plot_motion` -- ``animegraph plot``: synthesized motion against the ground truth
  when there is one, measured where the eye looks (:func:`animegraph.motion.measures.measures`),
  over the speech and its phone timeline, with the jump matches marked and each phone
  coloured by the recording its motion came from;
* :func:`plot_clips` -- the demo's picture of corpus clips (and their synthesis);
* :func:`plot_heldout`, :func:`plot_systems` -- mouth opening of a held-out clip against
  the search methods or every system (``scripts/eval_lipsync.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from animegraph.motion.files import Motion
from animegraph.motion.measures import measures, mouth_opening, point_kind
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
        axes[-1].plot(t, pitch, lw=1, color=colors[i % len(colors)], label=clip.spec.emotion)
    for k, (label, (markers, fps)) in enumerate((synthesized or {}).items()):
        t = np.arange(len(markers)) / fps
        color = colors[(len(clips) + k) % len(colors)]
        for ax, (_, a, b) in zip(axes[1:], MEASURES, strict=False):
            ax.plot(t, face.marker_distance(markers, a, b), "--", lw=1.2, color=color,
                    label=label)
        axes[-1].plot(t, head_pitch(markers), "--", lw=1.2, color=color, label=label)
    axes[-1].set_ylabel("head pitch (deg)")
    axes[-1].set_xlabel("time (s)")
    for ax in axes[1:]:  # every panel says which curve is which
        ax.legend(loc="upper right", fontsize=7, ncol=len(clips) + len(synthesized or {}),
                  framealpha=0.8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def head_pitch(markers: np.ndarray) -> np.ndarray:
    """Head pitch (degrees, positive tips the face down) of marker motion, per frame.

    The rotation of the rigid head markers from their rest positions
    (:func:`ingest.motion.rigid_fit`, Kabsch), read as the rig's pitch: the rig composes
    R = Ry Rx Rz (:func:`ingest.corpus.face.rigid_transform`), so R[1, 2] = -sin(pitch). On the
    demo's reference clip it follows the rig's own head_pitch control within 0.2 deg.

    Parameters
    ----------
    markers : np.ndarray, shape (n_frames, n_markers, 3)
        In :data:`ingest.corpus.face.MARKERS` order.

    Returns
    -------
    np.ndarray, shape (n_frames,)
        NaN where a head marker is missing.
    """
    from ingest.motion import rigid_fit

    head = [i for i, (_, _, group) in enumerate(face.MARKERS) if group == "head"]
    points = np.asarray(markers, dtype=np.float64)[:, head]
    out = np.full(len(points), np.nan)
    ok = np.isfinite(points).all(axis=(1, 2))
    if not ok.any():
        return out
    # rigid_fit takes each pose back onto the rest positions: the head's rotation is the
    # transpose, so its R[1, 2] is the fit's [2, 1].
    back, _ = rigid_fit(points[ok], face.marker_rest()[head])
    out[ok] = np.rad2deg(-np.arcsin(np.clip(back[:, 2, 1], -1.0, 1.0)))
    return out


def plot_heldout(model, clip, path: Path, *, methods=("exact", "window3", "random")) -> Path:
    """Mouth opening of a held-out clip: recorded against synthesized by ``methods``.

    Thin vertical lines mark the exact search's jump matches; phone labels run along the
    bottom.
    """
    from animegraph.apps import evaluate
    from animegraph.synthesis import render_nodes

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

    fig, ax = plt.subplots(figsize=(11, 3.5))
    truth = clip.motion.astype(np.float64)
    ax.plot(np.arange(len(truth)) / fps, mouth_opening(truth, names, kind), "k",
            lw=2, label="recorded")
    for k, (label, pred) in enumerate(predictions.items()):
        ax.plot(np.arange(len(pred)) / fps, mouth_opening(pred, names, kind),
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


def plot_motion(motion: Motion, path: Path, *, truth: Motion | None = None,
                phones: Sequence[dict] = (), audio: tuple[np.ndarray, int] | None = None,
                title: str = "", say: Callable[[str], object] | None = None,
                label: str = "synthesized") -> Path:
    """Plot synthesized ``motion`` (against ``truth``) with speech, phones and jumps.

    Parameters
    ----------
    motion, truth : Motion
        Channels are matched by name; the truth may be at another frame rate. A truth
        that shares only some of the motion's channels is drawn where it can be, and
        ``say`` is told so.
    phones : sequence of dict
        ``phone``, ``start``, ``end`` and optionally ``clip_id`` (source recording) and
        ``jump`` (a jump match into the phone), as in ``synth --explain-json``.
    audio : (samples, sample_rate), optional
    say : callable, optional
        Receives a line of news (the truth drawn in only some panels).
    label : str
        The motion's name in the legends (``animegraph plot``: its file's, since it may
        be a recorded snippet as well as a synthesized line).

    Raises
    ------
    DataError
        ``truth`` has none of the motion's channels, or too few to draw any measure.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from db.atomic import atomic_write

    rows = measures(motion.values, motion.names, reference=truth)
    # The truth measured as the motion is (a marker set missing a few markers too).
    truth_rows = dict(measures(truth.values, truth.names, point_kind(motion.names),
                               reference=truth)) if truth else {}
    if truth is not None:
        note = _truth_overlap(motion, truth, [label for label, _ in rows], truth_rows)
        if note and say is not None:
            say(note)
    top_panel = audio is not None or bool(phones)  # else it would be an empty box
    n_panels = int(top_panel) + len(rows)
    heights = [1.3] * int(top_panel) + [1.0] * len(rows)
    fig, axes = plt.subplots(n_panels, 1, figsize=(11, 1.2 + 1.6 * n_panels), sharex=True,
                             gridspec_kw={"height_ratios": heights})
    axes = np.atleast_1d(axes)
    if top_panel:
        top, axes = axes[0], axes[1:]
        if audio is not None:
            samples, rate = audio
            top.plot(np.arange(len(samples)) / rate, samples, lw=0.3, color="0.45")
            top.set_ylabel("speech")
        else:
            top.set_yticks([])
            top.set_ylabel("phones")
        _timeline(top, phones)
    t = np.arange(motion.n_frames) / motion.fps
    for ax, (measure, values) in zip(axes, rows, strict=True):
        if measure in truth_rows:
            tt = np.arange(truth.n_frames) / truth.fps
            ax.plot(tt, truth_rows[measure], color="k", lw=1.6, label="ground truth")
        ax.plot(t, values, color="C3", lw=1.1, label=label)
        ax.set_ylabel(measure, fontsize=8)
        for p in phones:
            if p.get("jump"):
                ax.axvline(p["start"], color="C0", lw=0.8, ls="--", alpha=0.7)
    for ax in axes:  # every panel says which curve is which
        ax.legend(loc="upper right", fontsize=7, ncol=2, framealpha=0.8)
    axes[-1].set_xlabel("time (s)")
    end = max(motion.duration, truth.duration if truth else 0.0,
              max((p["end"] for p in phones), default=0.0))
    axes[-1].set_xlim(0, end)
    fig.suptitle(" - ".join(s for s in (title, phones_subtitle(phones)) if s), fontsize=10)
    fig.tight_layout()
    with atomic_write(path) as handle:
        fig.savefig(handle, format="png", dpi=110)
    plt.close(fig)
    return Path(path)


def phones_subtitle(phones: Sequence[dict]) -> str:
    """"16 phones, 6 jump matches (dashed)" for a synthesis' explanation (it names each
    phone's recording); "11 phones" for a recording's labels, which have no jump to count."""
    if not phones:
        return ""
    if not any(p.get("clip_id") for p in phones):
        return f"{len(phones)} phones"
    n_jumps = sum(1 for p in phones if p.get("jump"))
    return f"{len(phones)} phones, {n_jumps} jump match{'es' * (n_jumps != 1)} (dashed)"


def _truth_overlap(motion: Motion, truth: Motion, labels: Sequence[str],
                   truth_rows: dict) -> str | None:
    """Check that ``truth`` is a ground truth of ``motion``'s channels: an error if no
    panel could show it, a note (else None) if it shares only some of them."""
    from db.errors import DataError

    have = set(truth.names)
    common = [n for n in motion.names if n in have]
    drawn = [label for label in labels if label in truth_rows]
    if not common or not drawn:
        if not common:
            mine = motion.names[0]
            theirs = next(iter(truth.names), "nothing")
            shared = (f"none of the motion's {len(motion.names)} channels is in the truth's "
                      f"{len(truth.names)} (the motion has {mine}, the truth {theirs})")
        else:
            lacking = next((n for n in motion.names if n not in have), motion.names[0])
            shared = (f"only {len(common)} of the motion's {len(motion.names)} channels are "
                      f"in the truth, too few for any plotted measure (it lacks {lacking})")
        raise DataError(f"the truth's channels are not the motion's: {shared}; give a "
                        f"truth with the motion's channels (a take of its database)")
    if len(common) == len(motion.names) and len(drawn) == len(labels):
        return None
    lacking = [n for n in motion.names if n not in have]
    return (f"the truth has {len(common)} of the motion's {len(motion.names)} channels"
            + (f" (not {lacking[0]}" + (", ..." if len(lacking) > 1 else "") + ")"
               if lacking else "")
            + f": ground truth drawn in {len(drawn)} of {len(labels)} panels")


#: Rows of clip-id labels at the jump lines in ``plot``, and the width of one character
#: of them as a share of the time axis (7 pt text on the 11-inch figure).
JUMP_LABEL_ROWS = 3
JUMP_LABEL_CHAR = 0.0075


def _timeline(ax, phones: Sequence[dict]) -> None:
    """Phone labels along the top panel; a bar per phone coloured by its source clip."""
    sources = list(dict.fromkeys(p.get("clip_id") for p in phones if p.get("clip_id")))
    colours = {s: f"C{i % 10}" for i, s in enumerate(sources)}
    trans = ax.get_xaxis_transform()
    span = max((p["end"] for p in phones), default=1.0) or 1.0
    # Clip ids at the jump lines: upright, legible, in up to JUMP_LABEL_ROWS staggered
    # rows; a label that would overlap every row is left out (its colour bar remains).
    char_s = span * JUMP_LABEL_CHAR
    row_ends = [-np.inf] * JUMP_LABEL_ROWS
    for k, p in enumerate(phones):
        ax.axvline(p["start"], color="0.85", lw=0.5, zorder=0)
        source = p.get("clip_id")
        if source:
            ax.axvspan(p["start"], p["end"], ymin=0.0, ymax=0.08, color=colours[source],
                       lw=0, alpha=0.8)
        if p.get("jump"):
            ax.axvline(p["start"], color="C0", lw=1.0, ls="--")
            row = next((r for r, end in enumerate(row_ends) if end < p["start"]), None)
            if source and row is not None:
                ax.text(p["start"], 0.12 + 0.15 * row, f" {source}", fontsize=7,
                        va="bottom", ha="left", transform=trans, color=colours[source])
                row_ends[row] = p["start"] + char_s * (len(source) + 2)
        if p["phone"] != "SIL":
            ax.text(0.5 * (p["start"] + p["end"]), 0.86 if k % 2 else 0.74, p["phone"],
                    ha="center", fontsize=6, transform=trans)
