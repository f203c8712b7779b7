"""``animegraph plot``: the picture an animator checks before trusting a result.

Synthesized motion against the ground truth when there is one, measured where the eye
looks (mouth opening, mouth width, brow height; the busiest curves of a curve
database), over the speech and its phone timeline, with the jump matches marked and each
phone coloured by the recording its motion came from.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from animegraph.motionio import Motion

#: (label, point a, point b) distances per kind of point set; the first is the mouth.
POINT_MEASURES = {
    "markers": (("mouth opening (mm)", "ulip_in_c", "llip_in_c"),
                ("mouth width (mm)", "lip_corner_r", "lip_corner_l"),
                ("brow to eye (mm)", "brow_r1", "eye_in_r")),
    "landmarks": (("mouth opening (mm)", "lm13", "lm14"),
                  ("mouth width (mm)", "lm61", "lm291"),
                  ("brow to eye (mm)", "lm105", "lm159")),
}


def point_kind(names: Sequence[str]) -> str | None:
    """``markers`` or ``landmarks`` if the channels hold that point set, else None."""
    names = set(names)
    for kind, measures in POINT_MEASURES.items():
        if all(f"{p}.x" in names for _, a, b in measures[:1] for p in (a, b)):
            return kind
    return None


def _distance(values: np.ndarray, names: Sequence[str], a: str, b: str) -> np.ndarray:
    index = {n: i for i, n in enumerate(names)}
    pa = values[:, [index[f"{a}.{x}"] for x in "xyz"]]
    pb = values[:, [index[f"{b}.{x}"] for x in "xyz"]]
    return np.linalg.norm(pa - pb, axis=1)


def measures(values: np.ndarray, names: Sequence[str], kind: str | None = None,
             *, max_curves: int = 4, reference: Motion | None = None
             ) -> list[tuple[str, np.ndarray]]:
    """Facial measures over time: list of (label, values of shape (n_frames,)).

    Point sets: the distances of :data:`POINT_MEASURES` that the channels allow. Curves:
    the jaw/mouth-opening curve if there is one, then the busiest curves (busiest in
    ``reference`` when given, so two motions show the same curves).
    """
    from animegraph.evaluate import MOUTH_CURVES

    kind = point_kind(names) if kind not in POINT_MEASURES else kind
    present = set(names)
    if kind in POINT_MEASURES:
        return [(label, _distance(values, names, a, b))
                for label, a, b in POINT_MEASURES[kind]
                if f"{a}.x" in present and f"{b}.x" in present]
    out = []
    mouth = next((n for n in MOUTH_CURVES if n in present), None)
    if mouth is not None:
        out.append((mouth, values[:, list(names).index(mouth)]))
    source = reference.values if reference is not None else values
    source_names = reference.names if reference is not None else names
    spread = np.nanstd(np.asarray(source, dtype=np.float64), axis=0)
    still = 1e-6 * max(float(np.nanmax(spread)), 1e-12) if len(spread) else 0.0
    for c in np.argsort(-spread):
        name = source_names[c]
        if name in present and name != mouth and len(out) < max_curves and spread[c] > still:
            out.append((name, values[:, list(names).index(name)]))
    return out


def measure(values: np.ndarray, names: Sequence[str], kind: str | None = None
            ) -> tuple[str, np.ndarray]:
    """The first of :func:`measures`: mouth opening where there is one."""
    found = measures(values, names, kind, max_curves=1)
    if not found:
        return "value", np.asarray(values, dtype=np.float64)
    return found[0]


def plot_motion(motion: Motion, path: Path, *, truth: Motion | None = None,
                phones: Sequence[dict] = (), audio: tuple[np.ndarray, int] | None = None,
                title: str = "") -> Path:
    """Plot synthesized ``motion`` (against ``truth``) with speech, phones and jumps.

    Parameters
    ----------
    motion, truth : Motion
        Channels are matched by name; the truth may be at another frame rate.
    phones : sequence of dict
        ``phone``, ``start``, ``end`` and optionally ``clip_id`` (source recording) and
        ``jump`` (a jump match into the phone), as in ``synth --explain-json``.
    audio : (samples, sample_rate), optional
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from db.atomic import atomic_write

    rows = measures(motion.values, motion.names, reference=truth)
    truth_rows = dict(measures(truth.values, truth.names, reference=truth)) if truth else {}
    n_panels = 1 + len(rows)
    heights = [1.3] + [1.0] * len(rows)
    fig, axes = plt.subplots(n_panels, 1, figsize=(11, 1.2 + 1.6 * n_panels), sharex=True,
                             gridspec_kw={"height_ratios": heights})
    axes = np.atleast_1d(axes)
    top = axes[0]
    if audio is not None:
        samples, rate = audio
        top.plot(np.arange(len(samples)) / rate, samples, lw=0.3, color="0.45")
        top.set_ylabel("speech")
    else:
        top.set_yticks([])
        top.set_ylabel("phones")
    _timeline(top, phones)
    t = np.arange(motion.n_frames) / motion.fps
    for ax, (label, values) in zip(axes[1:], rows, strict=True):
        if label in truth_rows:
            tt = np.arange(truth.n_frames) / truth.fps
            ax.plot(tt, truth_rows[label], color="k", lw=1.6, label="ground truth")
        ax.plot(t, values, color="C3", lw=1.1, label="synthesized")
        ax.set_ylabel(label, fontsize=8)
        for p in phones:
            if p.get("jump"):
                ax.axvline(p["start"], color="C0", lw=0.8, ls="--", alpha=0.7)
    if len(axes) > 1:
        axes[1].legend(loc="upper right", fontsize=7, ncol=2)
    axes[-1].set_xlabel("time (s)")
    end = max(motion.duration, truth.duration if truth else 0.0,
              max((p["end"] for p in phones), default=0.0))
    axes[-1].set_xlim(0, end)
    n_jumps = sum(1 for p in phones if p.get("jump"))
    subtitle = (f"{len(phones)} phones, {n_jumps} jump matches (dashed)" if phones else "")
    fig.suptitle(" - ".join(s for s in (title, subtitle) if s), fontsize=10)
    fig.tight_layout()
    with atomic_write(path) as handle:
        fig.savefig(handle, format="png", dpi=110)
    plt.close(fig)
    return Path(path)


def _timeline(ax, phones: Sequence[dict]) -> None:
    """Phone labels along the top panel; a bar per phone coloured by its source clip."""
    sources = list(dict.fromkeys(p.get("clip_id") for p in phones if p.get("clip_id")))
    colours = {s: f"C{i % 10}" for i, s in enumerate(sources)}
    trans = ax.get_xaxis_transform()
    for k, p in enumerate(phones):
        ax.axvline(p["start"], color="0.85", lw=0.5, zorder=0)
        source = p.get("clip_id")
        if source:
            ax.axvspan(p["start"], p["end"], ymin=0.0, ymax=0.08, color=colours[source],
                       lw=0, alpha=0.8)
        if p.get("jump"):
            ax.axvline(p["start"], color="C0", lw=1.0, ls="--")
            ax.text(p["start"], 0.12, source or "", rotation=90, fontsize=5, va="bottom",
                    transform=trans, color="C0")
        if p["phone"] != "SIL":
            ax.text(0.5 * (p["start"] + p["end"]), 0.86 if k % 2 else 0.74, p["phone"],
                    ha="center", fontsize=6, transform=trans)
