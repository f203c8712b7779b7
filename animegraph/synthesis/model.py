"""What synthesis needs from a motion database, loaded once (:class:`Model`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from animegraph.search.graph import AnimeGraph
from db.errors import DataError
from db.store import Database
from ingest.decompose import MotionDecomposer
from ingest.emotion.model import EmotionModel
from ingest.motion import fill_gaps, head_points, stabilize_points, unstabilize_points


@dataclass(frozen=True, eq=False)
class Model:
    """Everything synthesis needs from a database, loaded once."""

    db: Database
    graph: AnimeGraph
    decomposer: MotionDecomposer
    cutoffs: np.ndarray
    names: tuple[str, ...]
    groups: tuple[str, ...]
    kind: str
    head_reference: np.ndarray | None
    emotion_model: EmotionModel | None = None  # None: a database built before emotion models

    @classmethod
    def load(cls, path) -> Model:
        db = Database.open(path)
        arrays = db.arrays()
        channels = db.table("channels").to_pylist()
        try:
            emotion_model = EmotionModel.from_database(db)
        except DataError:
            emotion_model = None
        return cls(
            db=db, graph=AnimeGraph.from_database(db),
            decomposer=MotionDecomposer.from_arrays(arrays), cutoffs=arrays["ic_cutoff_hz"],
            names=tuple(c["name"] for c in channels), groups=tuple(c["group"] for c in channels),
            kind=channels[0]["kind"], head_reference=arrays.get("head_reference"),
            emotion_model=emotion_model,
        )

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


def to_world(motion: np.ndarray, groups, head_reference: np.ndarray | None) -> np.ndarray:
    """Motion (n_frames, n_channels) in the database's stored, head-stabilised space back
    in world coordinates (unchanged when the database has no rigid head group)."""
    if head_reference is not None and head_points(groups) >= 3:
        motion = unstabilize_points(motion, groups, head_reference)
    return motion
