"""Evaluation of the emotion model (Cao et al. 2005, §5.1.3 and §5.2).

* :func:`cross_validate` -- the paper's cross-validation of the emotion mapping: for an
  ordered pair of emotions (i, j), F_ij is learned from m - 1 of the m sentences recorded
  in both, the held-out sentence's motion in i is mapped into j, both motions are fitted
  into a unit cube and the RMS distance between corresponding frames is measured (paper:
  0.0117 for one neutral -> happy case). Every sentence is held out in turn, and two
  baselines are measured on the same frames: no mapping, and the mean emotion offset
  (e_j = e_i + mean(e_j - e_i) over the training correspondences).
* :func:`component_truth` -- on the synthetic corpus, which rig controls each independent
  component follows: the ground truth the speech/emotion split is checked against.

Choices where the paper is silent
---------------------------------
* "Corresponding frames": the recorded motion in j is aligned to the mapped motion (which
  keeps the timing of i) by the DTW on speech components used in learning (§5.2).
* "Unit cube": both motions are translated and scaled by one factor so that the *recorded*
  motion's bounding box (all markers, all frames) fits the unit cube, its longest side
  becoming 1; the same transform is applied to the mapped motion and to the baselines, so
  the three are measured in the same units.
* RMS distance: sqrt(mean over frames and markers of the squared 3-D distance) for point
  databases; over channels for others.
* Motions are in the database's head frame (the rigid head group as recorded), as stored.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from db.errors import DataError
from ingest.decompose import MotionDecomposer
from ingest.emotion.align import sample_at
from ingest.emotion.components import Aligner, parallel_groups, take_pairs
from ingest.emotion.mapping import KERNEL, N_CENTRES
from ingest.emotion.model import MIN_PARALLEL, EmotionModel, ParallelData, fit_mapping
from ingest.invariants import check_stored_decomposition

#: The paper's figure for its neutral -> happy cross-validation case (§5.2).
PAPER_RMS = 0.0117


@dataclass(frozen=True, eq=False)
class EmotionData:
    """A database's clips as the emotion evaluation needs them."""

    clip_ids: tuple[str, ...]
    motions: tuple[np.ndarray, ...]
    sources: tuple[np.ndarray, ...]
    emotions: tuple[str, ...]
    sentence_ids: tuple[str | None, ...]
    names: tuple[str, ...]
    fps: float
    decomposer: MotionDecomposer
    model: EmotionModel

    @classmethod
    def load(cls, db) -> EmotionData:
        """From a :class:`db.store.Database` (its clips, decomposer and emotion model)."""
        from ingest.tables import prepared_from_database

        clips = prepared_from_database(db)
        arrays = db.arrays()
        check_stored_decomposition(db, arrays, db.table("channels").to_pylist())
        dec = MotionDecomposer.from_arrays(arrays)
        return cls(
            clip_ids=tuple(c.clip_id for c in clips),
            motions=tuple(c.motion.astype(np.float64) for c in clips),
            sources=tuple(dec.transform(c.motion) for c in clips),
            emotions=tuple(c.emotion for c in clips),
            sentence_ids=tuple(c.sentence_id for c in clips),
            names=tuple(clips[0].schema.names), fps=float(db.manifest["fps"]),
            decomposer=dec, model=EmotionModel.from_database(db, arrays),
        )

    def parallel(self) -> ParallelData:
        return ParallelData(self.sources, self.emotions, self.sentence_ids,
                            Aligner(self.sources, self.fps))


def unit_cube_rms(pred: np.ndarray, truth: np.ndarray, names: Sequence[str]) -> float:
    """RMS distance between corresponding frames once ``truth`` fits the unit cube.

    Parameters
    ----------
    pred, truth : np.ndarray, shape (n_frames, n_channels)
    names : sequence of str
        Channel names (x/y/z triples make 3-D points).
    """
    pred = np.asarray(pred, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    points = len(names) % 3 == 0 and all(n.endswith((".x", ".y", ".z")) for n in names)
    if points:
        p = pred.reshape(len(pred), -1, 3)
        t = truth.reshape(len(truth), -1, 3)
        lo = t.reshape(-1, 3).min(axis=0)
        scale = float((t.reshape(-1, 3).max(axis=0) - lo).max())
        d2 = (((p - t) / scale) ** 2).sum(axis=2)
    else:
        scale = float(truth.max() - truth.min())
        d2 = ((pred - truth) / scale) ** 2
    return float(np.sqrt(d2.mean()))


@dataclass(frozen=True)
class HeldOut:
    """One held-out take pair of the cross-validation, for plotting.

    Attributes
    ----------
    source, mapped, offset, recorded : np.ndarray, shape (n_frames, n_channels)
        The motion in i, mapped into j, with the mean offset, and the recorded motion in j
        aligned to the source's frames.
    """

    src: str
    dst: str
    sentence: str
    clip_src: str
    clip_dst: str
    source: np.ndarray
    mapped: np.ndarray
    offset: np.ndarray
    recorded: np.ndarray
    e_source: np.ndarray
    e_mapped: np.ndarray
    e_recorded: np.ndarray


def held_out(data: EmotionData, src: str, dst: str, sentence: str, *,
             n_centres: int = N_CENTRES, kernel: str = KERNEL, offset: bool = False,
             parallel: ParallelData | None = None) -> list[HeldOut]:
    """Learn F_src,dst without ``sentence`` and map each of its takes in ``src`` (§5.2)."""
    parallel = parallel or data.parallel()
    split = data.model.split
    train = [s for s in parallel.sentences(src, dst) if s != sentence]
    if len(train) < MIN_PARALLEL - 1 or not train:
        raise DataError(f"{src}->{dst}: {len(train)} training sentences without {sentence}")
    f, mean_offset = fit_mapping(parallel, src, dst, train, split, n_centres=n_centres,
                                 kernel=kernel, offset=offset)
    e, s = split.emotion_components, split.speech_components
    g = parallel_groups(data.emotions, data.sentence_ids)[sentence]
    out = []
    for a, b in take_pairs(g[src], g[dst]):
        u = data.sources[a]
        mapped, shifted = u.copy(), u.copy()
        mapped[:, e] = f.transform(u[:, e])
        shifted[:, e] = u[:, e] + mean_offset
        where = parallel.aligner.positions(a, b, s)
        out.append(HeldOut(
            src=src, dst=dst, sentence=sentence, clip_src=data.clip_ids[a],
            clip_dst=data.clip_ids[b], source=data.motions[a],
            mapped=data.decomposer.inverse_transform(mapped),
            offset=data.decomposer.inverse_transform(shifted),
            recorded=sample_at(data.motions[b], where), e_source=u[:, e],
            e_mapped=mapped[:, e], e_recorded=sample_at(data.sources[b][:, e], where),
        ))
    return out


def cross_validate(data: EmotionData, pairs: Sequence[tuple[str, str]] | None = None, *,
                   n_centres: int = N_CENTRES, kernel: str = KERNEL,
                   offset: bool = False) -> list[dict]:
    """The paper's cross-validation for every ordered pair (or ``pairs``), every held-out
    sentence in turn.

    Returns
    -------
    list of dict
        One row per (pair, held-out sentence, take): ``src``, ``dst``, ``sentence``,
        ``clips``, ``n_train`` (sentences learned from) and the unit-cube RMS of the mapping
        (``mapped``) and of the baselines (``none``, ``offset``).

    Raises
    ------
    DataError
        Without emotion components, or with fewer than ``MIN_PARALLEL + 1`` sentences in
        both emotions of a requested pair.
    """
    if data.model.split.emotion_components.size == 0:
        raise DataError("the database has no emotion components: nothing to cross-validate")
    parallel = data.parallel()
    emotions = data.model.emotions
    if pairs is None:
        pairs = [(a, b) for a in emotions for b in emotions
                 if a != b and len(parallel.sentences(a, b)) > MIN_PARALLEL]
        if not pairs:
            raise DataError(f"cross-validation needs {MIN_PARALLEL + 1} sentences recorded in "
                            "two emotions; the database has fewer")
    rows = []
    for src, dst in pairs:
        sentences = parallel.sentences(src, dst)
        if len(sentences) <= MIN_PARALLEL:
            raise DataError(f"{src}->{dst}: {len(sentences)} parallel sentences, "
                            f"cross-validation needs {MIN_PARALLEL + 1}")
        for sentence in sentences:
            for h in held_out(data, src, dst, sentence, n_centres=n_centres, kernel=kernel,
                              offset=offset, parallel=parallel):
                rows.append({
                    "src": src, "dst": dst, "sentence": sentence,
                    "clips": f"{h.clip_src}->{h.clip_dst}", "n_train": len(sentences) - 1,
                    "mapped": unit_cube_rms(h.mapped, h.recorded, data.names),
                    "none": unit_cube_rms(h.source, h.recorded, data.names),
                    "offset": unit_cube_rms(h.offset, h.recorded, data.names),
                })
    return rows


def summarize(rows: Sequence[dict]) -> list[dict]:
    """Mean (and standard deviation) of each measure per ordered pair, then overall."""
    out = []
    keys = list(dict.fromkeys((r["src"], r["dst"]) for r in rows))
    for key in keys + [None]:
        sel = [r for r in rows if key is None or (r["src"], r["dst"]) == key]
        row = {"src": key[0] if key else "all", "dst": key[1] if key else "all",
               "n": len(sel)}
        for m in ("mapped", "none", "offset"):
            v = np.array([r[m] for r in sel])
            row[m] = float(v.mean())
            row[m + "_sd"] = float(v.std())
        row["mapped_best"] = float(np.mean([r["mapped"] <= min(r["none"], r["offset"])
                                            for r in sel]))
        out.append(row)
    return out


def component_truth(sources: Sequence[np.ndarray], controls: Sequence[np.ndarray],
                    control_names: Sequence[str], speech_controls: Sequence[str],
                    emotion_controls: Sequence[str], *, min_r2: float = 0.5) -> list[dict]:
    """Which rig controls each independent component follows (synthetic ground truth).

    Each component is regressed (least squares, with an intercept) on the speech controls
    and, separately, on the emotion controls over every frame of the corpus. Its true kind
    is ``emotion`` or ``speech`` when that regression explains at least ``min_r2`` of its
    variance and more than the other, else ``other`` (head motion, blinks, noise).

    Parameters
    ----------
    sources : sequence of np.ndarray, each (n_frames_k, n_ics)
    controls : sequence of np.ndarray, each (n_frames_k, n_controls)
        The generator's controls of the same clips (``<clip>.controls.csv``).

    Returns
    -------
    list of dict
        Per component: ``r2_speech``, ``r2_emotion``, ``truth``, ``top_control``, ``top_r``.
    """
    n = [min(len(s), len(c)) for s, c in zip(sources, controls, strict=True)]
    U = np.concatenate([np.asarray(s)[:k] for s, k in zip(sources, n, strict=True)])
    C = np.concatenate([np.asarray(c)[:k] for c, k in zip(controls, n, strict=True)])
    names = list(control_names)

    def r2(cols: list[int]) -> np.ndarray:
        X = np.column_stack([np.ones(len(C)), C[:, cols]])
        coef, *_ = np.linalg.lstsq(X, U, rcond=None)
        resid = U - X @ coef
        return 1.0 - resid.var(axis=0) / U.var(axis=0)

    r2_s = r2([names.index(c) for c in speech_controls])
    r2_e = r2([names.index(c) for c in emotion_controls])
    Uc, Cc = U - U.mean(axis=0), C - C.mean(axis=0)
    corr = (Uc.T @ Cc) / np.outer(np.linalg.norm(Uc, axis=0),
                                  np.maximum(np.linalg.norm(Cc, axis=0), 1e-12))
    out = []
    for k in range(U.shape[1]):
        if r2_e[k] >= min_r2 and r2_e[k] > r2_s[k]:
            truth = "emotion"
        elif r2_s[k] >= min_r2 and r2_s[k] > r2_e[k]:
            truth = "speech"
        else:
            truth = "other"
        top = int(np.argmax(np.abs(corr[k])))
        out.append({"component": k, "r2_speech": float(r2_s[k]), "r2_emotion": float(r2_e[k]),
                    "truth": truth, "top_control": names[top], "top_r": float(corr[k, top])})
    return out


def read_controls(corpus, clip_ids: Sequence[str]) -> tuple[list[np.ndarray], list[str]]:
    """The generator's controls of ``clip_ids`` from a synthetic corpus folder."""
    from pathlib import Path

    folder = Path(corpus) / "clips"
    out, header = [], None
    for clip in clip_ids:
        path = folder / f"{clip}.controls.csv"
        if not path.is_file():
            raise DataError(f"{path} is missing: not the synthetic corpus of this database")
        with open(path) as handle:
            header = handle.readline().strip().split(",")[2:]
        out.append(np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)[:, 2:])
    return out, header
