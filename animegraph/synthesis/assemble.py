"""From a matching anime sequence to continuous motion (Cao et al. 2005, §4.3).

Three steps, each optional so their effect can be measured:

* **Time-warping** — each anime's motion is warped onto its input phone's timing with
  the DTW path between the input's and the anime's prosody curves.
* **Blending** — at a jump match (a_i, a_i+1 not consecutive in a recording) the join is
  blended with a *helper pair* a_m -> a_n: connected nodes of the graph showing the same
  phoneme transition, time-warped onto a_i and a_i+1, mixed in with a weight that rises
  linearly to 1 at the joint and falls back (the paper's piecewise linear w). When the
  graph has no such pair, each side is continued by the frames that follow a_i / precede
  a_i+1 in their recordings (or extrapolated by velocity at a recording's end) and the
  two are cross-faded linearly.
* **Smoothing** — each independent component is low-pass filtered at the cutoff learned
  from the database (99 % of that component's energy below it;
  :func:`ingest.lowpass.smooth`, beside the learning of the cutoffs).

Beyond the paper, :func:`blend_k_best` averages the k best-matching animes of each phone
instead of joining one anime per phone (opt-in: ``synthesize(..., k_best=K)``), and
cross-fades each phone's mean into its neighbours' through the recorded transitions.

Motion is handled in independent-component space, shape (n_frames, n_ics), at the
database's frame rate.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from animegraph.search.dtw import dtw, warp_indices, warp_indices_many
from animegraph.search.graph import PHONE_INDEX, AnimeGraph, clip_motion_means
from db.errors import ParameterError
from ingest.lowpass import smooth

#: :func:`blend_k_best` weighs the r-th ranked anime (r = 1, 2, ...) by ``r ** -RANK_DECAY``.
#: Measured against equal weights (0) and 1 (docs/results/lipsync.md, "Choices inside the
#: default"): 0.5 was as good or better
#: on every data set.
RANK_DECAY = 0.5
#: PostOptions.helper: the helper pair's motion as recorded (the paper), or anchored.
HELPER_MODES = ("paper", "anchored", "anchored-nonspeech")


@dataclass(frozen=True)
class Phone:
    """An input phone: label, start and end (s), its prosody curve (m, 9) and, beyond the
    paper, its phone posteriorgram (q, 39) or None."""

    phone: str
    start: float
    end: float
    prosody: np.ndarray
    posteriors: np.ndarray | None = None


@dataclass(frozen=True)
class PostOptions:
    """Which post-processing steps run (all, as in the paper, by default), and how k-best
    averages (beyond the paper)."""

    time_warp: bool = True  # DTW on prosody; False: stretch each anime uniformly
    blend: bool = True  # blend at jump matches (k-best: at every phone join)
    smooth: bool = True  # low-pass with the learned cutoffs
    #: How a helper pair's motion enters the blend at a jump: "paper" as recorded (§4.3);
    #: "anchored" displaced onto the two animes' poses at the blend's ends (:func:`anchor`);
    #: "anchored-nonspeech" the same for all but the speech components (§5.1.3).
    helper: str = "paper"
    #: Beyond the paper, k-best only (:func:`blend_k_best`): each anime enters the mean
    #: relative to its recording's mean pose, and the utterance takes the mean pose of the
    #: recordings it draws on. None (the default): when the database's clips come from
    #: more than one speaker or session (:func:`animegraph.synthesis.recentres`); False:
    #: the animes as recorded.
    recentre: bool | None = None

    def __post_init__(self) -> None:
        if self.helper not in HELPER_MODES:
            raise ParameterError(f"helper must be one of {HELPER_MODES}, got {self.helper!r}")


def output_frames(phones: Sequence[Phone], fps: float) -> tuple[int, list[tuple[int, int]]]:
    """Number of output frames and each phone's [first, stop) frame range (tiling)."""
    end = phones[-1].end
    n = max(1, int(round(end * fps)))
    edges = [min(n, max(0, int(round(p.start * fps)))) for p in phones] + [n]
    ranges = []
    for i in range(len(phones)):
        a, b = edges[i], max(edges[i + 1], edges[i])
        ranges.append((a, b))
    return n, ranges


def warp_anime(graph: AnimeGraph, node: int, phone: Phone, n_out: int, *,
               time_warp: bool = True) -> np.ndarray:
    """The motion of ``node`` warped onto ``n_out`` frames of ``phone``.

    Returns
    -------
    np.ndarray, shape (n_out, n_ics)
    """
    return warp_animes(graph, np.array([node]), phone, n_out, time_warp=time_warp)[0]


def warp_animes(graph: AnimeGraph, nodes: np.ndarray, phone: Phone, n_out: int, *,
                time_warp: bool = True, positions: np.ndarray | None = None) -> np.ndarray:
    """The motions of ``nodes`` each warped onto ``n_out`` frames of ``phone`` (§4.3).

    Each anime is played with the input phone's timing: the DTW alignment of the two
    prosody curves (:func:`warp_positions`) says which anime frame each input frame
    shows. An anime or a phone of a single prosody frame (or ``time_warp`` False) is
    stretched uniformly instead.

    Parameters
    ----------
    graph : AnimeGraph
    nodes : np.ndarray of int, shape (k,)
    phone : Phone
    n_out : int
    time_warp : bool, optional
    positions : np.ndarray, shape (k, len(phone.prosody)), optional
        The rows of :func:`animegraph.search.dtw.warp_indices_many` for ``nodes`` (rows
        of animes that are stretched are not read); computed when not given.

    Returns
    -------
    np.ndarray, shape (k, n_out, n_ics)
    """
    nodes = np.asarray(nodes, dtype=np.int64)
    first = graph.motion_offsets[nodes]
    frames = graph.motion_offsets[nodes + 1] - first
    prosody = graph.prosody_offsets[nodes + 1] - graph.prosody_offsets[nodes]
    u = (np.arange(n_out) + 0.5) / n_out if n_out else np.zeros(0)
    frac = np.tile(u, (len(nodes), 1))  # (k, n_out): where in each anime, 0 to 1
    n_in = len(phone.prosody)
    warped = np.flatnonzero((frames > 1) & (prosody > 1)) if (time_warp and n_out
                                                               and n_in > 1) else []
    if len(warped):
        if positions is None:
            positions = np.zeros((len(nodes), n_in))
            positions[warped] = warp_indices_many(
                [phone.prosody], graph.prosody_values, graph.prosody_offsets,
                [nodes[warped]])[0]
        at = u * (n_in - 1)  # each output frame's place among the input's prosody frames
        src = positions[warped].astype(np.float64)  # a copy: the ends pinned, see warp_positions
        src[:, 0], src[:, -1] = 0.0, prosody[warped] - 1.0
        # np.interp on the integer grid 0 .. n_in - 1, every row at once (its arithmetic:
        # slope times the distance from the left knot, plus the left value)
        j = np.minimum(np.floor(at).astype(np.int64), n_in - 2)
        v = (src[:, j + 1] - src[:, j]) * (at - j) + src[:, j]
        frac[warped] = np.clip(v / (prosody[warped] - 1)[:, None], 0.0, 1.0)
    pos = frac * (frames - 1)[:, None]
    lo = np.floor(pos).astype(np.int64)
    hi = np.minimum(lo + 1, (frames - 1)[:, None])
    t = (pos - lo)[:, :, None]
    values = graph.motion_values
    return ((1 - t) * values[first[:, None] + lo].astype(np.float64)
            + t * values[first[:, None] + hi].astype(np.float64))


def warp_positions(c_input: np.ndarray, c_anime: np.ndarray) -> np.ndarray:
    """Fractional anime prosody frame shown at each input prosody frame (§4.3).

    The DTW alignment of the two prosody curves (:func:`animegraph.search.dtw.warp_indices`),
    with its ends pinned: the first input frame shows the anime's first frame and the
    last its last. Where DTW matches several anime frames to an end frame, the mean
    would start the anime late (or end it early), and two consecutive animes of one
    recording would then no longer meet where they met in the recording.

    Parameters
    ----------
    c_input : np.ndarray, shape (n, d)
    c_anime : np.ndarray, shape (m, d)

    Returns
    -------
    np.ndarray of float64, shape (n,)
        Non-decreasing, from 0 to m - 1 (for n >= 2).
    """
    src = warp_indices(len(c_input), dtw(c_input, c_anime).path)
    src[0] = 0.0
    if len(src) > 1:
        src[-1] = len(c_anime) - 1.0
    return src


def find_helper_pair(graph: AnimeGraph, a: int, b: int, *, emotion: int | None = None):
    """A connected pair (m, n = next_node[m]) with the phonemes of ``a`` and ``b``.

    Prefers pairs of ``emotion`` and, among them, the one whose joint is closest to the
    jump's two sides. Returns None if the graph shows no such transition.
    """
    pa, pb = graph.node_phone[a], graph.node_phone[b]
    m = graph.by_phone[pa]
    n = graph.next_node[m]
    ok = n >= 0
    m, n = m[ok], n[ok]
    keep = graph.node_phone[n] == pb
    m, n = m[keep], n[keep]
    if len(m) == 0:
        return None
    score = (np.linalg.norm(graph.last_pcs[m] - graph.last_pcs[a], axis=1)
             + np.linalg.norm(graph.first_pcs[n] - graph.first_pcs[b], axis=1))
    if emotion is not None:
        score = score + 1e6 * (graph.node_emotion[m] != emotion)
    k = int(np.argmin(score))
    return int(m[k]), int(n[k])


def anchor(helper: np.ndarray, first: np.ndarray, last: np.ndarray) -> np.ndarray:
    """A helper pair's motion displaced to start at ``first`` and end at ``last``.

    Beyond the paper (``PostOptions(helper="anchored")``). §4.3 blends the helper pair's
    motion in as recorded, with weight 1 at the joint, so there the face is the helper
    recording's: its transition, and also its pose, which can be far from the two animes'
    (a weaker smile, in the demo: the lip corner spikes to neutral levels). Anchored, the
    helper adds only its transition: a linear displacement (motion warping, Witkin &
    Popović 1995) moves it onto the animes' poses at the blend's first and last frames.
    ``"anchored-nonspeech"`` does so for the emotion and other components only: the
    helper pair is chosen as an example of the phoneme transition (§4.3), which the
    speech components carry; its smile, brows and head pose are its recording's.

    Parameters
    ----------
    helper : np.ndarray, shape (n_frames, n_ics)
    first, last : np.ndarray, shape (n_ics,)
        The anime motion at the blend's first and last frames.

    Returns
    -------
    np.ndarray, shape (n_frames, n_ics)
    """
    u = np.linspace(0.0, 1.0, len(helper))[:, None]
    return helper + (1 - u) * (first - helper[0]) + u * (last - helper[-1])


def _continuation(graph: AnimeGraph, node: int, n: int, *, forward: bool) -> np.ndarray:
    """``n`` frames after (or before) ``node`` in its recording, extrapolated past its ends."""
    frames = []
    step = graph.next_node if forward else graph.prev_node
    cur = int(step[node])
    have = 0
    while cur >= 0 and have < n:
        block = graph.motion(cur).astype(np.float64)
        frames.append(block if forward else block[::-1])
        have += len(block)
        cur = int(step[cur])
    own = graph.motion(node).astype(np.float64)
    if have >= n:
        out = np.concatenate(frames)[:n]
    else:
        # The recording ends: continue with the node's last velocity.
        edge = own if forward else own[::-1]
        last = (np.concatenate([edge] + frames) if frames else edge)
        vel = last[-1] - last[-2] if len(last) > 1 else np.zeros(last.shape[1])
        extra = last[-1] + vel * np.arange(1, n - have + 1)[:, None]
        out = np.concatenate(frames + [extra]) if frames else extra
    return out if forward else out[::-1]


def assemble(graph: AnimeGraph, nodes: Sequence[int], phones: Sequence[Phone], *,
             cutoffs: np.ndarray | None = None, options: PostOptions | None = None,
             emotion: int | None = None,
             speech: np.ndarray | None = None) -> tuple[np.ndarray, list[dict]]:
    """Continuous motion for a matching anime sequence.

    Parameters
    ----------
    graph : AnimeGraph
    nodes : sequence of int, length n
        The anime chosen for each input phone.
    phones : sequence of Phone, length n
        The input phones, tiling the utterance.
    cutoffs : np.ndarray, shape (n_ics,), optional
        Low-pass cutoff per independent component (Hz); needed for smoothing.
    options : PostOptions, optional
    emotion : int, optional
        Emotion index preferred for helper pairs.
    speech : np.ndarray of int, optional
        The speech components (:class:`ingest.emotion.components.ComponentSplit`), left
        as recorded by ``PostOptions(helper="anchored-nonspeech")`` (all are anchored
        when not given).

    Returns
    -------
    motion : np.ndarray, shape (n_frames, n_ics)
        At ``graph.fps``; ``n_frames = round(phones[-1].end * fps)``.
    joins : list of dict
        For each jump match: the input index, and how it was blended
        (``"helper"`` with the pair, or ``"continuation"``).
    """
    opts = options or PostOptions()
    fps = graph.fps
    n, ranges = output_frames(phones, fps)
    n_ics = graph.motion_values.shape[1]
    pieces = [warp_anime(graph, int(a), p, b - s, time_warp=opts.time_warp)
              for a, p, (s, b) in zip(nodes, phones, ranges, strict=True)]
    motion = np.zeros((n, n_ics))
    for (s, b), piece in zip(ranges, pieces, strict=True):
        motion[s:b] = piece
    joins = []
    for i in range(len(nodes) - 1):
        a, b = int(nodes[i]), int(nodes[i + 1])
        if graph.next_node[a] == b:
            continue
        join = {"index": i, "from": a, "to": b}
        (s0, s1), (_, s2) = ranges[i], ranges[i + 1]
        if opts.blend and s1 > s0 and s2 > s1:
            pair = find_helper_pair(graph, a, b, emotion=emotion)
            if pair is not None:
                m, k = pair
                helper = np.concatenate([
                    warp_anime(graph, m, phones[i], s1 - s0, time_warp=opts.time_warp),
                    warp_anime(graph, k, phones[i + 1], s2 - s1, time_warp=opts.time_warp),
                ])
                if opts.helper != "paper":
                    cols = (np.arange(n_ics) if opts.helper == "anchored" or speech is None
                            else np.setdiff1d(np.arange(n_ics), speech))
                    helper[:, cols] = anchor(helper[:, cols], motion[s0, cols],
                                             motion[s2 - 1, cols])
                t = np.arange(s0, s2, dtype=np.float64)
                w = np.where(t <= s1, (t - s0) / max(s1 - s0, 1), (s2 - 1 - t) /
                             max(s2 - 1 - s1, 1))
                w = np.clip(w, 0.0, 1.0)[:, None]
                motion[s0:s2] = (1 - w) * motion[s0:s2] + w * helper
                join.update(blend="helper", helper=(m, k))
            else:
                q, p = s2 - s1, s1 - s0
                left = np.concatenate([motion[s0:s1], _continuation(graph, a, q, forward=True)])
                right = np.concatenate([_continuation(graph, b, p, forward=False),
                                        motion[s1:s2]])
                w = np.linspace(0.0, 1.0, s2 - s0)[:, None]
                motion[s0:s2] = (1 - w) * left + w * right
                join.update(blend="continuation")
        else:
            join.update(blend="none")
        joins.append(join)
    if opts.smooth and cutoffs is not None:
        motion = smooth(motion, cutoffs, fps)
    return motion, joins


def rank_weights(n: int) -> np.ndarray:
    """Weights of :func:`blend_k_best`'s ``n`` ranked animes: ``r ** -RANK_DECAY`` for
    r = 1..n, summing to 1; shape (n,)."""
    w = (np.arange(n) + 1.0) ** -RANK_DECAY
    return w / w.sum()


@functools.lru_cache(maxsize=2)  # per graph (hashed by identity): batch reuses it
def recording_means(graph: AnimeGraph) -> np.ndarray:
    """Each recording's mean motion over its animes' frames (read-only): the graph's
    ``clip_means`` when it was loaded with them, else
    :func:`animegraph.search.graph.clip_motion_means` (every anime's motion read).

    Returns
    -------
    np.ndarray, shape (len(graph.clip_ids), n_ics)
        Row ``c``: the mean of ``graph.motion_values`` over the frames of the animes of
        clip ``c`` (zeros for a clip without frames).
    """
    means = graph.clip_means if graph.clip_means is not None else clip_motion_means(graph)
    means = means.view()
    means.flags.writeable = False
    return means


def blend_k_best(graph: AnimeGraph, ranked: Sequence[np.ndarray], phones: Sequence[Phone], *,
                 cutoffs: np.ndarray | None = None,
                 options: PostOptions | None = None,
                 positions: Sequence[np.ndarray | None] | None = None) -> np.ndarray:
    """Motion that averages several animes per input phone (beyond the paper).

    Each phone's frames are the weighted mean of the motions of its ``ranked`` nodes, each
    time-warped onto the phone as in :func:`assemble`, the r-th weighted by
    ``r ** -RANK_DECAY`` (:data:`RANK_DECAY`); the result is then smoothed with the
    learned cutoffs. One anime per phone is a single noisy sample of how the phone
    can look; the mean of the few whose audio matches best is a better estimate (on
    real data with recognized phones, docs/results/lipsync.md, "FACEGOOD" and "talkingface").

    Averaged neighbours are no longer single recordings to join as §4.3 does at a jump
    match. With ``options.blend`` (the default) each join is cross-faded instead through
    the transitions the animes were recorded with: each phone's mean is carried into
    the halves of its neighbours by the animes recorded next to its own
    (:func:`_recorded_neighbours`: those that show the input's neighbouring phone, as the
    helper pairs of §4.3 show the jump's phoneme transition), and the two estimates of a
    frame between two phones' centres are mixed with weights that move linearly from one
    centre to the other (overlap-add with triangular windows, which sum to one). Where no
    anime shows the transition, the phone's own mean stands. Without ``blend`` the
    phones' means are cut at their boundaries.

    With ``options.recentre`` true each anime enters the mean as its motion
    relative to its recording's mean pose (:func:`recording_means`), and the utterance's
    motion is then offset by the mean pose of the recordings it drew on (weighted as the
    animes, over all its frames). Recordings differ in their rest pose (another speaker,
    session, head placement or tracking), and a phone's animes drawn from several of them
    carry those differences as a jump from phone to phone that no speech made: the
    per-speaker and per-session mean normalisation of speech features (cepstral mean
    normalisation), and the motion relative to the speaker's own face that speech-driven
    animation across speakers predicts (Cudeiro et al., "Capture, learning, and synthesis
    of 3D speaking styles", CVPR 2019, §4: displacements from each subject's template).
    One offset for the whole utterance keeps what the recordings share, such as an
    emotion's expression when the animes are of one emotion. ``recentre`` False or None
    averages the animes as recorded (synthesis decides None beforehand:
    :func:`animegraph.synthesis.recentres`).

    Parameters
    ----------
    graph : AnimeGraph
    ranked : sequence of np.ndarray of int, length n
        The nodes averaged for each input phone (:func:`animegraph.search.k_best`).
    phones : sequence of Phone, length n
    cutoffs : np.ndarray, shape (n_ics,), optional
        Needed for smoothing.
    options : PostOptions, optional
        ``time_warp``, ``blend``, ``smooth`` and ``recentre`` apply.
    positions : sequence of (np.ndarray or None), length n, optional
        With ``time_warp``: each phone's time-warps of its ranked animes, as
        :func:`blend_positions` gives them (computed if None; a stream keeps those of
        the phones it has warped already, :mod:`animegraph.live.window`).

    Returns
    -------
    np.ndarray, shape (n_frames, n_ics)
        At ``graph.fps``, as :func:`assemble`.
    """
    opts = options or PostOptions()
    n, ranges = output_frames(phones, graph.fps)
    n_ics = graph.motion_values.shape[1]
    motion = np.zeros((n, n_ics))
    means = recording_means(graph) if opts.recentre else None
    offset, used = np.zeros(n_ics), 0.0
    before, after = [], []  # per phone: its animes' recorded neighbours, (mean, weight)
    if not opts.time_warp:
        positions = [None] * len(phones)
    elif positions is None:
        positions = blend_positions(graph, ranked, phones)
    for i, (nodes, phone, (s, b)) in enumerate(zip(ranked, phones, ranges, strict=True)):
        nodes = np.asarray(nodes, dtype=np.int64)
        w = rank_weights(len(nodes))
        own = (means[graph.node_clip[nodes]] if means is not None
               else np.zeros((len(nodes), n_ics)))  # (k, n_ics)
        pieces = warp_animes(graph, nodes, phone, b - s, time_warp=opts.time_warp,
                             positions=positions[i])
        motion[s:b] = np.tensordot(w, pieces - own[:, None, :], axes=1)
        if means is not None and b > s:
            offset += (b - s) * (w @ own)
            used += b - s
        if opts.blend:
            before.append(_recorded_neighbours(
                graph, nodes, w, own, phones[i - 1], ranges[i - 1][1] - ranges[i - 1][0],
                before=True) if i > 0 else (None, 0.0))
            after.append(_recorded_neighbours(
                graph, nodes, w, own, phones[i + 1], ranges[i + 1][1] - ranges[i + 1][0],
                before=False) if i + 1 < len(phones) else (None, 0.0))
    if opts.blend:
        motion = _cross_fade(motion, ranges, before, after)
    if means is not None and used > 0:
        motion += offset / used
    if opts.smooth and cutoffs is not None:
        motion = smooth(motion, cutoffs, graph.fps)
    return motion


def blend_positions(graph: AnimeGraph, ranked: Sequence[np.ndarray],
                    phones: Sequence[Phone]) -> list[np.ndarray | None]:
    """:func:`warp_animes`'s ``positions`` for every phone's ``ranked`` nodes, in one
    compiled pass over the utterance (rows of animes that are stretched are zero; None
    for a phone of one prosody frame or less): shapes (len(ranked[i]), n_prosody_i)."""
    out: list[np.ndarray | None] = [None] * len(phones)
    lengths = np.diff(graph.prosody_offsets)
    use = [i for i, p in enumerate(phones) if len(p.prosody) > 1]
    rows = [np.asarray(ranked[i], dtype=np.int64) for i in use]
    keep = [lengths[r] > 1 for r in rows]
    kept = [r[k] for r, k in zip(rows, keep, strict=True)]
    warps = warp_indices_many([phones[i].prosody for i in use], graph.prosody_values,
                              graph.prosody_offsets, kept)
    for i, r, k, w in zip(use, rows, keep, warps, strict=True):
        out[i] = np.zeros((len(r), len(phones[i].prosody)))
        out[i][k] = w
    return out


def _recorded_neighbours(graph: AnimeGraph, nodes: np.ndarray, w: np.ndarray,
                         own: np.ndarray, phone: Phone, n_out: int, *,
                         before: bool) -> tuple[np.ndarray | None, float]:
    """What the animes ``nodes`` of one input phone show of its neighbour ``phone``.

    The animes recorded just before ``nodes`` (``before``) or just after them, of those
    that show ``phone``'s phoneme: each stretched onto the neighbour's ``n_out`` frames,
    relative to its recording's pose as the phone's own mean is, and averaged with the
    weights ``w`` renormalised over them.

    Parameters
    ----------
    nodes : np.ndarray of int, shape (k,)
    w : np.ndarray, shape (k,)
        Their weights (summing to 1).
    own : np.ndarray, shape (k, n_ics)
        The pose each enters the mean relative to (zeros: as recorded).
    phone : Phone
        The neighbouring input phone.
    n_out : int
        Its number of frames.
    before : bool
        The neighbour is the phone before (else after).

    Returns
    -------
    mean : np.ndarray, shape (n_out, n_ics), or None
        None when the neighbour has no frames or no anime shows it.
    share : float
        The share of ``w`` the animes shown carry (0 with None).
    """
    nb = (graph.prev_node if before else graph.next_node)[nodes]
    shows = (nb >= 0) & (graph.node_phone[np.maximum(nb, 0)]
                         == PHONE_INDEX.get(phone.phone, -1))
    if n_out == 0 or not shows.any():
        return None, 0.0
    # every shown anime stretched uniformly onto the neighbour's frames, all at once
    pieces = warp_animes(graph, nb[shows], phone, n_out, time_warp=False) - own[shows][:, None, :]
    share = float(w[shows].sum())
    return np.tensordot(w[shows] / share, pieces, axes=1), share


def _cross_fade(motion: np.ndarray, ranges: Sequence[tuple[int, int]],
                before: Sequence[tuple[np.ndarray | None, float]],
                after: Sequence[tuple[np.ndarray | None, float]]) -> np.ndarray:
    """Each phone's frames mixed with its neighbours' recorded continuations.

    ``motion`` (n_frames, n_ics) holds each phone's own mean in its ``ranges``;
    ``before[i]`` / ``after[i]`` are phone i's animes' recorded neighbours over phone
    i - 1's / i + 1's frames, with the share of weight they carry
    (:func:`_recorded_neighbours`). Between the centres of phones i and i + 1, the
    weight of phone i + 1's estimate rises linearly from 0 to 1 (times the share its
    estimate carries there, the rest staying with the phone's own mean).
    """
    out = motion.copy()
    centres = [(s + b - 1) / 2.0 for s, b in ranges]
    for j, (s, b) in enumerate(ranges):
        if b <= s:
            continue
        t = np.arange(s, b, dtype=np.float64)
        own = motion[s:b]
        for k, neighbour in ((j - 1, after[j - 1] if j > 0 else (None, 0.0)),
                             (j + 1, before[j + 1] if j + 1 < len(ranges) else (None, 0.0))):
            estimate, share = neighbour
            if estimate is None:
                continue
            side = (t < centres[j]) if k < j else (t >= centres[j])  # the half facing k
            # The triangular window of phone k: 1 at its centre, 0 at this phone's.
            reach = max(abs(centres[j] - centres[k]), 1e-9)
            raw = np.clip(1.0 - np.abs(t[side] - centres[k]) / reach, 0.0, 1.0)[:, None]
            out[s:b][side] = (((1.0 - raw) * own[side] + share * raw * estimate[side])
                              / ((1.0 - raw) + share * raw))
    return out
