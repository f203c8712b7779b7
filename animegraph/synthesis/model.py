"""What synthesis needs from a motion database, loaded once (:class:`Model`)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from animegraph.search.graph import AnimeGraph
from animegraph.search.mapped import load_graph
from db.store import Database
from ingest.clip import stored_schema
from ingest.emotion.model import EmotionModel, NoEmotionModel
from ingest.invariants import check_stored_decomposition
from ingest.motion import fill_gaps, head_points, stabilize_points, unstabilize_points
from ingest.unmixing import Unmixing


def sessions_of(corpora, speakers) -> tuple[tuple[str, str], ...]:
    """The distinct (corpus, speaker) pairs of clips, sorted; a missing value is "".

    A session is what ingest pools a lip-audio lag over (:func:`ingest.lag.group_key`):
    one speaker in one corpus folder, and the clips of a folder that name no speaker are
    one speaker's. Two folders of unnamed speakers (two actors, or one actor on two
    days, framed and tracked afresh) are two sessions, as two named speakers are.
    """
    return tuple(sorted({(str(c or ""), str(s or ""))
                         for c, s in zip(corpora, speakers, strict=True)}))


def read_channels(db: Database) -> tuple[list[dict], tuple[str, ...], tuple[str, ...], str]:
    """(rows, names, groups, kind) of the database's motion channels (its ``channels``
    table, read as ingest reads it: :func:`ingest.tables.stored_schema`), or DataError
    naming the table if it does not hold up (the summary in its manifest is not relied on
    for the kind)."""
    channels = db.table("channels").to_pylist()
    schema = stored_schema(db, channels)
    return channels, schema.names, schema.groups, schema.kind


@dataclass(frozen=True, eq=False)
class Model:
    """Everything synthesis needs from a database, loaded once."""

    db: Database
    graph: AnimeGraph
    decomposer: Unmixing
    cutoffs: np.ndarray
    names: tuple[str, ...]
    groups: tuple[str, ...]
    kind: str
    head_reference: np.ndarray | None
    emotion_model: EmotionModel | None = None  # None: a database built before emotion models

    @classmethod
    def load(cls, path) -> Model:
        """Load what synthesis needs from the database at ``path``, checked.

        Raises
        ------
        DataError
            If the database is missing or does not hold up: one line naming the file
            (a database is shared between people, so it is untrusted input).
        """
        db = Database.open(path)
        arrays = db.arrays()
        graph = load_graph(db)
        channels, names, groups, kind = read_channels(db)
        try:
            decomposer = Unmixing.from_arrays(arrays)
            cutoffs = np.asarray(arrays["ic_cutoff_hz"], dtype=np.float64)
            _check_shapes(graph, decomposer, cutoffs, names, arrays.get("head_reference"))
        except (KeyError, IndexError, TypeError, ValueError) as exc:
            raise db.damaged("model_arrays", f"{type(exc).__name__}: {exc}") from None
        check_stored_decomposition(db, arrays, channels)
        try:
            emotion_model = EmotionModel.from_database(db, arrays)
        except NoEmotionModel:
            emotion_model = None
        except (KeyError, IndexError, TypeError, ValueError, AttributeError) as exc:
            raise db.damaged("model_arrays", f"emotion model: {type(exc).__name__}: "
                             f"{exc}") from None
        return cls(
            db=db, graph=graph, decomposer=decomposer, cutoffs=cutoffs, names=names,
            groups=groups, kind=kind, head_reference=arrays.get("head_reference"),
            emotion_model=emotion_model,
        )

    @cached_property
    def sessions(self) -> tuple[tuple[str, str], ...]:
        """The recording sessions of the database's clips, sorted: :func:`sessions_of`
        their corpus and speaker columns. k-best recentres each anime on its recording by
        default when there is more than one. Read on first use, not at load: only k-best
        asks."""
        try:
            table = self.db.table("clips", columns=["corpus", "speaker"])
            return sessions_of(table.column("corpus").to_pylist(),
                               table.column("speaker").to_pylist())
        except (KeyError, TypeError, ValueError) as exc:
            raise self.db.damaged("clips", f"{type(exc).__name__}: {exc}") from None

    def to_channels(self, ics: np.ndarray) -> np.ndarray:
        """Motion in the database's channels (world coordinates for a head group)."""
        return to_world(self.decomposer.inverse_transform(ics), self.groups,
                        self.head_reference)

    @property
    def rigid_head(self) -> bool:
        """True if the database stores motion head-stabilised (a rigid head group)."""
        return self.head_reference is not None and head_points(self.groups) >= 3

    def to_local(self, motion: np.ndarray) -> np.ndarray:
        """Motion (n_frames, n_channels) in the database's channels, gaps filled, in the
        stored (head-stabilised) space that its PCA/ICA model describes: the inverse of
        :meth:`to_channels` before the decomposition."""
        filled, _ = fill_gaps(np.asarray(motion, dtype=np.float64), self.names)
        if self.rigid_head:
            return stabilize_points(filled, self.groups, self.head_reference)
        return filled


def _check_shapes(graph: AnimeGraph, decomposer: Unmixing, cutoffs: np.ndarray,
                  names: tuple[str, ...], head_reference: np.ndarray | None) -> None:
    """ValueError unless the graph, the PCA/ICA model and the channels fit together."""
    n_pcs, n_channels = decomposer.components_.shape
    if len(names) != n_channels or graph.n_channels != n_channels:
        raise ValueError(f"{len(names)} channels, {n_channels} in the PCA model, "
                         f"{graph.n_channels} in the manifest")
    if decomposer.mean_.shape != (n_channels,) or n_pcs < 1:
        raise ValueError("the channel mean does not fit the PCA components")
    if decomposer.ica_mean_.shape != (n_pcs,) or not np.isfinite(decomposer.mixing_).all():
        raise ValueError("the ICA model does not fit the PCA components")
    if graph.motion_values.shape[1] != n_pcs or graph.first_pcs.shape[1] != n_pcs:
        raise ValueError(f"anime motion has {graph.motion_values.shape[1]} components, the "
                         f"model {n_pcs}")
    if cutoffs.shape != (n_pcs,) or not (cutoffs > 0).all():
        raise ValueError("ic_cutoff_hz does not give one positive cutoff per component")
    if head_reference is not None and (head_reference.ndim != 2 or head_reference.shape[1] != 3):
        raise ValueError(f"head_reference has shape {head_reference.shape}")


def to_world(motion: np.ndarray, groups, head_reference: np.ndarray | None) -> np.ndarray:
    """Motion (n_frames, n_channels) in the database's stored, head-stabilised space back
    in world coordinates (unchanged when the database has no rigid head group)."""
    if head_reference is not None and head_points(groups) >= 3:
        motion = unstabilize_points(motion, groups, head_reference)
    return motion
