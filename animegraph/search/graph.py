"""The Anime Graph in memory: flat arrays over every anime node of a database.

Cao et al. (2005, §4.1): every recorded utterance is a linked list of anime nodes
a = <P, C, M, E>; the set of these lists is the Anime Graph. Here the graph is a
struct of arrays (after the motion-matching databases of game animation): one entry
per node for its phoneme, emotion, clip and links, and ragged blocks (values plus
offsets) for its prosody curve C and its motion M, so a search touches contiguous
memory and loading is a handful of column reads.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from animegraph.search.dtw import mark_finite
from db.arrow import numbers
from db.errors import DataError, ParameterError
from db.store import Database
from ingest.speech.phones import PHONES

#: Index of each phone in :data:`ingest.speech.phones.PHONES`.
PHONE_INDEX = {p: i for i, p in enumerate(PHONES)}
#: Animes whose curves are read at once when the graph is loaded (a few tens of MB).
CURVE_BATCH_ROWS = 64 * 1024


@dataclass(frozen=True, eq=False)
class AnimeGraph:
    """Every anime node of a database.

    Attributes
    ----------
    node_phone : np.ndarray of int16, shape (n_nodes,)
        Index into :data:`ingest.speech.phones.PHONES`.
    node_emotion : np.ndarray of int16, shape (n_nodes,)
        Index into ``emotions``.
    node_clip : np.ndarray of int32, shape (n_nodes,)
        Index into ``clip_ids``.
    position : np.ndarray of int32, shape (n_nodes,)
        Place of the node in its recording.
    next_node, prev_node : np.ndarray of int64, shape (n_nodes,)
        The following / preceding node of the same recording, -1 at its ends.
    start_frame, end_frame : np.ndarray of int32, shape (n_nodes,)
        Frames [start, end) of the node in its clip.
    start_time, end_time : np.ndarray of float32, shape (n_nodes,)
        Seconds.
    prosody_offsets : np.ndarray of int64, shape (n_nodes + 1,)
        Node ``a``'s prosody curve is ``prosody_values[prosody_offsets[a]:prosody_offsets[a+1]]``.
    prosody_values : np.ndarray of float32, shape (n_prosody_frames, n_prosody)
        RASTA-PLP frames (100 per second, 9 coefficients).
    motion_offsets : np.ndarray of int64, shape (n_nodes + 1,)
    motion_values : np.ndarray of float32, shape (n_motion_frames, n_ics)
        Motion curves in independent-component space.
    first_pcs, last_pcs : np.ndarray of float32, shape (n_nodes, n_pcs)
        First and last motion frame of each node in principal-component space, where
        Euclidean distance equals distance in the original channels (up to what PCA
        left out): the jump cost's frames (Eq. 4).
    by_phone : tuple of np.ndarray of int64
        ``by_phone[p]``: the nodes whose phoneme is ``PHONES[p]``, ascending.
    clip_ids, emotions : tuple of str
    fps : float
    n_channels : int
        Channels of the original motion (for RMS distances).
    posterior_offsets : np.ndarray of int64, shape (n_nodes + 1,), or None
    posterior_values : np.ndarray of float32, shape (n_posterior_frames, 39), or None
        Beyond the paper: each node's phone posteriorgram (50 frames per second,
        :mod:`ingest.speech.posteriorgram`), as ``prosody_*``; None when the database has
        none (built without hama, or before posteriorgrams).
    clip_means : np.ndarray of float64, shape (len(clip_ids), n_ics), or None
        Each recording's mean motion (:func:`clip_motion_means`), when it was computed
        with the graph (:mod:`animegraph.search.mapped`): k-best's recentring then need
        not read every anime's motion. None: computed on first use.
    """

    node_phone: np.ndarray
    node_emotion: np.ndarray
    node_clip: np.ndarray
    position: np.ndarray
    next_node: np.ndarray
    prev_node: np.ndarray
    start_frame: np.ndarray
    end_frame: np.ndarray
    start_time: np.ndarray
    end_time: np.ndarray
    prosody_offsets: np.ndarray
    prosody_values: np.ndarray
    motion_offsets: np.ndarray
    motion_values: np.ndarray
    first_pcs: np.ndarray
    last_pcs: np.ndarray
    by_phone: tuple[np.ndarray, ...]
    clip_ids: tuple[str, ...]
    emotions: tuple[str, ...]
    fps: float
    n_channels: int
    posterior_offsets: np.ndarray | None = None
    posterior_values: np.ndarray | None = None
    clip_means: np.ndarray | None = None

    @property
    def n_nodes(self) -> int:
        return int(self.node_phone.shape[0])

    def prosody(self, node: int) -> np.ndarray:
        """Prosody curve C of ``node``: shape (n_frames, n_prosody)."""
        return self.prosody_values[self.prosody_offsets[node]:self.prosody_offsets[node + 1]]

    def motion(self, node: int) -> np.ndarray:
        """Motion M of ``node`` in independent components: shape (n_frames, n_ics)."""
        return self.motion_values[self.motion_offsets[node]:self.motion_offsets[node + 1]]

    def nbytes(self) -> int:
        """Memory held by the graph's arrays."""
        total = 0
        for value in self.__dict__.values():
            if isinstance(value, np.ndarray):
                total += value.nbytes
            elif isinstance(value, tuple) and value and isinstance(value[0], np.ndarray):
                total += sum(v.nbytes for v in value)
        return total

    @classmethod
    def from_database(cls, db: Database, empty=None) -> AnimeGraph:
        """Load the graph of ``db`` (its animes table, sorted by node id).

        Every array is checked before the graph exists (the compiled search kernels
        index with them unchecked): links in [-1, n) and joining consecutive nodes of
        one recording, frame ranges and row counts that fit the stored curves, finite
        values, a known phoneme per node.

        Raises
        ------
        DataError
            If the database has no animes or its animes table does not hold up (the
            message names the file and the problem).

        ``empty(name, shape)``, if given, allocates the float32 array of curve ``name``
        ("prosody", "motion", "posteriors", "first_pcs", "last_pcs"; default
        :func:`numpy.empty`): :mod:`animegraph.search.mapped` has them written into files.
        """
        try:
            return cls._from_database(db, empty)
        except (KeyError, IndexError, TypeError, ValueError, pa.ArrowException) as exc:
            raise db.damaged("animes", f"{type(exc).__name__}: {exc}") from None

    @classmethod
    def _from_database(cls, db: Database, empty=None) -> AnimeGraph:
        # Two passes: the per-node columns whole, then the curves a batch at a time into
        # their arrays (the whole table, then a sorted copy of it, were 2.3 GB of the
        # load's peak a million animes: docs/results/speed.md, "A database of 100 hours").
        columns = [
            "node_id", "clip_id", "emotion", "position", "phoneme", "start_frame",
            "end_frame", "start_time", "end_time", "prosody_frames", "n_frames",
            "prev_node", "next_node",
        ]
        # Phone posteriorgrams (beyond the paper) are stored only by ingest --posteriorgrams.
        posteriors = {"posteriors", "posterior_frames"} <= set(db.columns("animes"))
        if posteriors:
            columns += ["posterior_frames"]
        t = db.table("animes", columns=columns)
        n = t.num_rows
        if n == 0:
            raise DataError(f"database {db.root} has no anime nodes")
        node_id = numbers(t.column("node_id"))
        order = np.argsort(node_id, kind="stable")  # table row of each node
        if not np.array_equal(node_id[order], np.arange(n)):
            raise DataError(f"database {db.root} is damaged: node ids are not 0..{n - 1}")

        def codes(name: str) -> tuple[np.ndarray, tuple[str, ...]]:
            encoded = t.column(name).combine_chunks().dictionary_encode()
            return (numbers(encoded.indices).astype(np.int32)[order],
                    tuple(encoded.dictionary.to_pylist()))

        def ints(name: str, dtype) -> np.ndarray:
            return _ints(t, name, dtype)[order]

        clip_codes, clip_ids = codes("clip_id")
        emotion_codes, emotions = codes("emotion")
        phone_codes, phone_names = codes("phoneme")
        try:
            remap = np.array([PHONE_INDEX[p] for p in phone_names], dtype=np.int16)
        except KeyError as exc:
            raise DataError(f"database {db.root} has an unknown phoneme {exc}") from None
        node_phone = remap[phone_codes]
        frames = {"prosody": ints("prosody_frames", np.int64),
                  "motion": ints("n_frames", np.int64)}
        if posteriors:
            frames["posteriors"] = ints("posterior_frames", np.int64)
        frames |= {"first_pcs": np.ones(n, np.int64), "last_pcs": np.ones(n, np.int64)}
        curves = _read_curves(db, frames, empty)
        manifest = db.manifest
        posterior_values, posterior_offsets = curves.get("posteriors", (None, None))
        graph = cls(
            node_phone=node_phone, node_emotion=emotion_codes.astype(np.int16),
            node_clip=clip_codes, position=ints("position", np.int32),
            next_node=_links(t.column("next_node"))[order],
            prev_node=_links(t.column("prev_node"))[order],
            start_frame=ints("start_frame", np.int32), end_frame=ints("end_frame", np.int32),
            start_time=numbers(t.column("start_time")).astype(np.float32)[order],
            end_time=numbers(t.column("end_time")).astype(np.float32)[order],
            prosody_offsets=curves["prosody"][1], prosody_values=curves["prosody"][0],
            motion_offsets=curves["motion"][1], motion_values=curves["motion"][0],
            first_pcs=curves["first_pcs"][0], last_pcs=curves["last_pcs"][0],
            by_phone=tuple(np.flatnonzero(node_phone == p).astype(np.int64)
                           for p in range(len(PHONES))),
            clip_ids=clip_ids, emotions=emotions, fps=float(manifest["fps"]),
            n_channels=int(manifest["n_channels"]),
            posterior_offsets=posterior_offsets, posterior_values=posterior_values,
        )
        graph.check()
        return graph

    def check(self, values: bool = True) -> None:
        """ValueError unless every array is in range and consistent (see from_database).

        ``values`` False leaves out what reads the curves' values (finite, posteriors in
        (0, 1]): every page of them. :mod:`animegraph.search.mapped` checks them once,
        when it writes them, and their shapes at every load."""
        n = self.n_nodes
        for name in ("next_node", "prev_node"):
            links = getattr(self, name)
            if links.shape != (n,) or ((links < -1) | (links >= n)).any():
                raise ValueError(f"{name} outside [-1, {n})")
        nxt = np.flatnonzero(self.next_node >= 0)
        if (self.prev_node[self.next_node[nxt]] != nxt).any() or (
                self.node_clip[self.next_node[nxt]] != self.node_clip[nxt]).any():
            raise ValueError("next_node and prev_node do not link one recording's nodes")
        if (self.prev_node >= 0).sum() != nxt.size:
            raise ValueError("next_node and prev_node disagree")
        if ((self.start_frame < 0) | (self.end_frame <= self.start_frame)).any():
            raise ValueError("frame ranges are empty or negative")
        if np.diff(self.motion_offsets).min(initial=1) < 1 or np.diff(
                self.prosody_offsets).min(initial=1) < 1:
            raise ValueError("a node without motion or prosody frames")
        for name in ("prosody", "motion", "posterior"):
            offsets, rows = getattr(self, f"{name}_offsets"), getattr(self, f"{name}_values")
            if offsets is None:
                continue
            if (offsets.shape != (n + 1,) or offsets[0] != 0 or rows.ndim != 2
                    or offsets[-1] != rows.shape[0]):
                raise ValueError(f"{name}_offsets do not fit {name}_values")
        for name in ("start_time", "end_time") + (
                ("motion_values", "first_pcs", "last_pcs") if values else ()):
            if not np.isfinite(getattr(self, name)).all():
                raise ValueError(f"{name} not finite")
        # The curves the DTW reads: checked here once (and made read-only), so that its
        # pair functions need not scan them again on every call. A mapped graph's were
        # checked when they were written; marking them would read every page, so its
        # DTW checks the few curves a query touches instead.
        if values:
            try:
                mark_finite(self.prosody_values)
            except ParameterError:
                raise ValueError("prosody_values not finite") from None
        if self.posterior_values is not None:
            post = self.posterior_values
            if len(self.posterior_offsets) != n + 1 or np.diff(
                    self.posterior_offsets).min(initial=1) < 1:
                raise ValueError("a node without posteriorgram frames")
            if values:
                try:
                    mark_finite(post)
                except ParameterError:
                    raise ValueError("posteriorgram values outside (0, 1]") from None
            if values and ((post <= 0).any() or (post > 1).any()):
                raise ValueError("posteriorgram values outside (0, 1]")
        if self.first_pcs.shape != self.last_pcs.shape or self.first_pcs.shape[0] != n:
            raise ValueError("first_pcs and last_pcs shapes differ")
        if not (np.isfinite(self.fps) and self.fps > 0 and self.n_channels > 0):
            raise ValueError(f"fps {self.fps} / n_channels {self.n_channels} in the manifest")
        n_clips = len(self.clip_ids)
        if self.node_clip.shape != (n,) or ((self.node_clip < 0) | (
                self.node_clip >= n_clips)).any():
            raise ValueError(f"node_clip outside [0, {n_clips})")
        if self.clip_means is not None and self.clip_means.shape != (
                n_clips, self.motion_values.shape[1]):
            raise ValueError(f"clip_means has shape {self.clip_means.shape}")


def clip_motion_means(graph: AnimeGraph) -> np.ndarray:
    """Each recording's mean motion over its animes' frames.

    Returns
    -------
    np.ndarray of float64, shape (len(graph.clip_ids), n_ics)
        Row ``c``: the mean of ``graph.motion_values`` over the frames of the animes of
        clip ``c`` (zeros for a clip without frames).
    """
    off = graph.motion_offsets
    counts = np.diff(off).astype(np.float64)
    sums = np.zeros((len(counts), graph.motion_values.shape[1]))
    full = counts > 0
    sums[full] = np.add.reduceat(graph.motion_values, off[:-1][full], axis=0, dtype=np.float64)
    n_clips = len(graph.clip_ids)
    total = np.zeros((n_clips, sums.shape[1]))
    np.add.at(total, graph.node_clip, sums)
    frames = np.bincount(graph.node_clip, weights=counts, minlength=n_clips)
    return total / np.maximum(frames, 1.0)[:, None]


def _links(column: pa.ChunkedArray) -> np.ndarray:
    if not pa.types.is_integer(column.type):
        raise TypeError(f"links must be integers, not {column.type}")
    return numbers(column, null=-1).astype(np.int64)


def _ints(t: pa.Table, name: str, dtype) -> np.ndarray:
    column = t.column(name)
    if not pa.types.is_integer(column.type) or column.null_count:
        raise TypeError(f"{name} must be integers without nulls, not {column.type}")
    values = numbers(column).astype(np.int64)
    info = np.iinfo(dtype)
    if ((values < info.min) | (values > info.max)).any():
        raise ValueError(f"{name} outside the range of {np.dtype(dtype).name}")
    return values.astype(dtype)


def _read_curves(db: Database, frames: dict[str, np.ndarray], empty=None,
                 ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The list columns ``frames`` names of the animes table, each as (values of shape
    (total frames, width) float32, row offsets of shape (n_nodes + 1,)) in node order.

    ``frames[c]``, shape (n_nodes,): the frames of each node in column ``c`` (a list of
    ``frames * width`` numbers a node). Read a batch at a time (:meth:`Database.batches`)
    and copied to each node's place: the column is never held whole. ``empty(name,
    shape)`` allocates a column's array (:meth:`AnimeGraph.from_database`)."""
    n = len(next(iter(frames.values())))
    offsets, out, width, arrays = {}, {}, {}, {}
    for c, rows in frames.items():
        if (rows < 1).any():
            raise ValueError(f"a node with no frames in {c}")
        offsets[c] = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(rows, out=offsets[c][1:])
    seen = np.zeros(n, dtype=np.int64)
    for part in db.batches("animes", ["node_id", *frames], CURVE_BATCH_ROWS):
        ids = numbers(part.column("node_id")).astype(np.int64)
        if ((ids < 0) | (ids >= n)).any():
            raise ValueError("node ids out of range")
        np.add.at(seen, ids, 1)
        for c, rows in frames.items():
            column = part.column(c)
            if column.null_count:
                raise ValueError(f"{c}: {column.type} column has nulls")
            lengths = _list_lengths(column)
            need = rows[ids]
            if c not in width:
                width[c] = int(lengths.sum()) // max(int(need.sum()), 1)
                if width[c] < 1:
                    raise ValueError(f"{c}: no values")
                shape = (int(offsets[c][-1]), width[c])
                arrays[c] = (np.empty(shape, dtype=np.float32) if empty is None
                             else empty(c, shape))
                out[c] = arrays[c].reshape(-1)
            if not np.array_equal(lengths, need * width[c]):
                raise ValueError(f"{c}: a node's list does not hold its frames")
            values = _list_values(column, int(lengths.sum()))
            start = offsets[c][ids] * width[c]
            if ids.size and np.array_equal(ids, np.arange(ids[0], ids[0] + ids.size)):
                out[c][start[0]:start[0] + values.size] = values  # nodes in order
            else:
                src = np.zeros(ids.size, dtype=np.int64)
                np.cumsum(lengths[:-1], out=src[1:])
                out[c][np.repeat(start - src, lengths) + np.arange(values.size)] = values
    if (seen != 1).any():
        raise ValueError("the curves' node ids differ from the nodes'")
    return {c: (arrays[c], offsets[c]) for c in frames}


def _list_lengths(column: pa.ChunkedArray) -> np.ndarray:
    """Length of every row of a list column, shape (n_rows,)."""
    if not (pa.types.is_list(column.type) or pa.types.is_large_list(column.type)):
        raise TypeError(f"a list column was expected, not {column.type}")
    parts = [np.diff(numbers(chunk.offsets)) for chunk in column.chunks]
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


def _list_values(column: pa.ChunkedArray, size: int) -> np.ndarray:
    """The values of a list column's rows end to end, as float32 (size,), chunk by chunk
    (``flatten`` honours a chunk's slice of its values)."""
    values = np.empty(size, dtype=np.float32)
    k = 0
    for chunk in column.chunks:
        part = numbers(chunk.flatten())
        values[k:k + part.size] = part
        k += part.size
    return values
