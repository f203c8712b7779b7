"""A statistical model's predicted trajectory guiding which recorded animes are used
(beyond the paper, behind an option: ``synthesize(..., guide=...)``, ``synth --guide``).

Recognised phones are often wrong on real speech (docs/results/lipsync.md), and the
paper's search then ranks animes of the wrong phone by an audio cost alone. The
talking-head literature's remedy is *trajectory-guided sample selection*: a statistical
audio-to-visual model predicts a visual trajectory for the input speech, and recorded
samples are chosen by their distance to it (L. Wang, X. Qian, W. Han & F. K. Soong,
"Photo-real lips synthesis with trajectory-guided sample selection", 7th ISCA Speech
Synthesis Workshop 2010, 217-222; "Synthesizing photo-real talking head via
trajectory-guided sample selection", Interspeech 2010, 446-449), the *target cost* of
unit selection (A. J. Hunt & A. W. Black, "Unit selection in a concatenative speech
synthesis system using a large speech database", ICASSP 1996; HMM-guided in Z.-H. Ling &
R.-H. Wang, ICASSP 2007). Here:

* the guide is a baseline of :mod:`animegraph.baselines` fitted on the database (mu-mlp,
  Hong et al. 2002; av-hmm, Terissi et al. 2013): its per-frame prediction for the input
  audio is the target trajectory;
* :func:`target_costs`: each candidate anime's motion, stretched uniformly onto the
  phone's output frames (as assembly does without prosody warping), against the target
  over those frames: the mean per-frame Euclidean distance in principal-component space
  (the database's motion space, variance-weighted);
* :func:`guided_costs`: the target cost is added to the audio cost of Eq. 5 after
  scaling it to the audio cost's median over the phone's candidates (equal weights,
  :data:`TARGET_WEIGHT`, set before measuring), so the search and k-best ranking use the
  sum in place of C_audio and the paper's other weights keep their meaning;
* :func:`blend_guide`: the synthesized motion is averaged with the guide's
  (:data:`GUIDE_BLEND`, 0.5: the plain mean of two predictors, model averaging as in
  Hastie, Tibshirani & Friedman, The Elements of Statistical Learning, §8.8; equal weights
  rather than fitted ones, the robust choice of forecast combination, Bates & Granger
  1969, Clemen 1989).

Measured (docs/results/lipsync.md, "FACEGOOD" and "talkingface"): the blend beat k-best
20 without a guide and mu-mlp on FACEGOOD and talkingface, within and across speakers;
the guided ranking did not hold across speakers (a guide fitted on other speakers is a
poor target; lipsync.md, "Options measured against the default"), so
``synthesize`` ranks by the guide only when asked (``guide_rank``, ``synth --guide-rank``).
"""

from __future__ import annotations

import numpy as np

from animegraph.synthesis.assemble import output_frames
from db.errors import ParameterError
from ingest.motion import interpolate

#: Baselines that can guide (``synth --guide``), and a mean of two (``a+b``: the mean of
#: their predictions); ``"none"`` turns guiding off.
GUIDES = ("mu-mlp", "av-hmm", "ppg-ridge", "mu-mlp+ppg-ridge")
#: Weight of the target cost against the audio cost, both scaled to the same median over
#: a phone's candidates (equal weights, as chosen before measuring).
TARGET_WEIGHT = 1.0
#: Share of the guide's own motion in the output when blending (a plain mean of two).
GUIDE_BLEND = 0.5
#: Candidates warped at once by :func:`target_costs` (bounds the (c, m, n_ics) block).
CHUNK = 256


def guide_trajectory(model, predictor, audio: np.ndarray, sample_rate: int, phones, *,
                     emotion: str | None = None) -> np.ndarray:
    """The guide's predicted motion for the utterance, in independent components.

    Parameters
    ----------
    model : animegraph.synthesis.Model
    predictor : animegraph.baselines.base.BaselineModel, or a sequence of them
        Fitted on the same database (its channels are the database's). Several: the
        mean of their predictions (equal weights, as :func:`blend_guide`).
    audio : np.ndarray, shape (n_samples,)
    sample_rate : int
    phones : sequence of Phone
        The utterance's phones (they fix the number of output frames).
    emotion : str, optional
        Passed on if the predictor was trained on it.

    Returns
    -------
    np.ndarray, shape (n_frames, n_ics)
        At ``model.graph.fps``, ``n_frames`` as :func:`output_frames`.
    """
    if isinstance(predictor, list | tuple):
        return np.mean([guide_trajectory(model, p, audio, sample_rate, phones, emotion=emotion)
                        for p in predictor], axis=0)
    predictor.check_channels(model.names, f"database {model.db.root}")
    n, _ = output_frames(phones, model.graph.fps)
    emotions = getattr(predictor, "emotions_", ())
    fps = float(predictor.fps_)
    m = max(1, int(round(n * fps / model.graph.fps)))
    pred = predictor.predict(audio, sample_rate, n_frames=m,
                             emotion=emotion if emotion in emotions else None)
    if m != n:  # another frame rate than the graph's: resample linearly
        pred = interpolate(np.arange(m) / fps, pred, np.arange(n) / model.graph.fps)
    return model.decomposer.transform(pred)


def target_costs(graph, mixing: np.ndarray, phones, nodes, guide: np.ndarray) -> list[np.ndarray]:
    """Distance of every candidate anime's motion to the guide over its phone.

    Parameters
    ----------
    graph : animegraph.search.AnimeGraph
    mixing : np.ndarray, shape (n_pcs, n_ics)
        The decomposition's mixing matrix (independent -> principal components).
    phones : sequence of Phone, length n
    nodes : sequence of np.ndarray of int, length n
        ``nodes[i]``: the candidates of phone ``i``.
    guide : np.ndarray, shape (n_frames, n_ics)
        :func:`guide_trajectory`.

    Returns
    -------
    list of np.ndarray of float64, shapes (len(nodes[i]),)
        The mean over the phone's output frames of the Euclidean distance, in principal-
        component space, between the candidate stretched onto the frames and the guide;
        zeros for a phone with no output frame.
    """
    n, ranges = output_frames(phones, graph.fps)
    if guide.shape[0] != n:
        raise ParameterError(f"the guide has {guide.shape[0]} frames, the phones {n}")
    off, values = graph.motion_offsets, graph.motion_values
    out = []
    for cands, (s, b) in zip(nodes, ranges, strict=True):
        cands = np.asarray(cands, dtype=np.int64)
        if b <= s or len(cands) == 0:
            out.append(np.zeros(len(cands)))
            continue
        u = (np.arange(b - s) + 0.5) / (b - s)
        target = guide[s:b]
        costs = []
        for k in range(0, len(cands), CHUNK):
            part = cands[k:k + CHUNK]
            length = (off[part + 1] - off[part])[:, None]
            pos = u[None, :] * (length - 1)
            lo = np.floor(pos).astype(np.int64)
            hi = np.minimum(lo + 1, length - 1)
            frac = (pos - lo)[..., None]
            first = off[part][:, None]
            warped = values[first + lo] * (1.0 - frac) + values[first + hi] * frac
            diff = (warped - target[None]) @ mixing.T
            costs.append(np.sqrt(np.sum(diff**2, axis=-1)).mean(axis=1))
        out.append(np.concatenate(costs))
    return out


def guided_costs(audio: list[np.ndarray], target: list[np.ndarray],
                 weight: float = TARGET_WEIGHT) -> list[np.ndarray]:
    """C_audio plus the target cost scaled to C_audio's median over each phone's candidates.

    Parameters
    ----------
    audio, target : list of np.ndarray, shapes (n_candidates_i,)
    weight : float
        Of the scaled target cost (1: equal to the audio cost).

    Returns
    -------
    list of np.ndarray of float64, shapes (n_candidates_i,)
    """
    out = []
    for a, t in zip(audio, target, strict=True):
        a = np.asarray(a, dtype=np.float64)
        t = np.asarray(t, dtype=np.float64)
        scale_t = float(np.median(t)) if len(t) else 0.0
        scale_a = float(np.median(a)) if len(a) else 0.0
        if scale_t > 0 and scale_a > 0:
            out.append(a + weight * scale_a / scale_t * t)
        else:
            out.append(a)
    return out


def guide_names(predictor) -> tuple[str, ...]:
    """The baselines a guide is made of (``("mu-mlp", "ppg-ridge")`` for their mean); ()
    for None."""
    if predictor is None:
        return ()
    if isinstance(predictor, list | tuple):
        return tuple(name for p in predictor for name in guide_names(p))
    return (str(predictor.method),)


def check_guide_use(share: float, rank: bool) -> None:
    """ParameterError unless the guide does something: a share in [0, 1], not 0 without
    ranking."""
    if not 0.0 <= share <= 1.0:
        raise ParameterError(f"the guide's share must be in [0, 1], got {share!r}")
    if share == 0 and not rank:
        raise ParameterError("a guide with no share of the output and no ranking does "
                             "nothing: give a share > 0 or rank by it")


def blend_guide(ics: np.ndarray, guide: np.ndarray, share: float = GUIDE_BLEND) -> np.ndarray:
    """``(1 - share) * ics + share * guide`` (shapes (n_frames, n_ics), equal)."""
    if not 0.0 <= share <= 1.0:
        raise ParameterError(f"the guide's share must be in [0, 1], got {share!r}")
    if ics.shape != guide.shape:
        raise ParameterError(f"motion {ics.shape} and guide {guide.shape} differ in shape")
    return (1.0 - share) * ics + share * guide
