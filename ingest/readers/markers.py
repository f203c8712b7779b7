"""Marker clips: 3D marker trajectories (C3D, TRC or marker CSV) with their speech.

Two layouts, read the same way:

- the project's synthetic corpus (:mod:`ingest.corpus.synthetic`): ``corpus.json``,
  ``markers.csv`` and ``clips/<id>.{c3d,wav,json,phones.csv}``;
- a generic folder: ``<stem>.c3d`` / ``<stem>.trc`` / ``<stem>.csv`` (marker CSV) with
  ``<stem>.wav``, optionally ``<stem>.txt`` (transcript), ``<stem>.json`` (``text``,
  ``emotion``, ``speaker``, ``sentence_id``) and phone labels ``<stem>.phones.csv`` /
  ``<stem>.TextGrid`` / ``<stem>.lab``.

Motion groups come from a ``markers.csv`` (columns ``label`` and ``group``) in the
clip's folder or the one above; markers it does not list, or all markers without one,
are in group ``"other"``. The transcript file wins over the JSON's ``text``.
"""

from __future__ import annotations

import logging
from pathlib import Path

from db.errors import DataError
from ingest.clip import ChannelSchema, RawClip, checksum_files
from ingest.formats import MOTION_READERS
from ingest.formats.text import read_csv_records
from ingest.formats.wav import read_wav
from ingest.readers.common import (
    GROUPS,
    ClipSource,
    check_durations,
    check_motion,
    metadata_fields,
    read_fps,
    read_json_object,
    transcript_and_labels,
)

logger = logging.getLogger(__name__)


def read_marker_table(path: Path) -> dict[str, str]:
    """Read ``markers.csv``: marker label -> motion group.

    Raises
    ------
    DataError
        If the file is not UTF-8 CSV with ``label`` and ``group`` columns, a group is not
        one of :data:`ingest.readers.common.GROUPS`, or a label repeats.
    """
    _, rows = read_csv_records(path, "marker table", ("label", "group"))
    table: dict[str, str] = {}
    for where, row in rows:
        label, group = row["label"], row["group"]
        if not label:
            continue
        if group not in GROUPS:
            raise DataError(f"{where}: unknown motion group {group!r} (expected one of "
                            f"{GROUPS})")
        if label in table:
            raise DataError(f"{where}: marker {label!r} listed twice")
        table[label] = group
    return table


def load_markers(source: ClipSource) -> RawClip:
    """Read one marker clip (synthetic corpus or generic folder).

    Raises
    ------
    DataError
        On a missing, unreadable or truncated file, a marker NaN in every frame, an
        empty transcript, bad labels or metadata, or audio and motion durations that
        disagree.
    """
    motion_path = source.source
    audio_path = source.file("audio")
    if audio_path is None:
        raise DataError(f"{motion_path}: no audio file {motion_path.stem}.wav beside it")
    reader = MOTION_READERS.get(motion_path.suffix.lower())
    if reader is None:
        raise DataError(f"{motion_path}: no marker reader for {motion_path.suffix!r} files")
    data = reader(motion_path)

    table_path = source.file("marker_table")
    table = read_marker_table(table_path) if table_path else {}
    if table:
        unlisted = [label for label in data.labels if label not in table]
        if unlisted:
            logger.info("%s: %d markers not in %s, group 'other': %s", motion_path,
                        len(unlisted), table_path, ", ".join(unlisted[:5]))
    groups = [table.get(label, "other") for label in data.labels]
    motion = check_motion(data.points.reshape(data.n_frames, 3 * data.n_markers), data.labels,
                          motion_path, "marker", stride=3)
    try:
        schema = ChannelSchema.for_points("markers", data.labels, groups, "mm")
    except DataError as exc:
        raise DataError(f"{motion_path}: {exc}") from None

    audio, sample_rate = read_wav(audio_path)
    audio_seconds = len(audio) / sample_rate
    check_durations(data.n_frames, data.rate, audio_seconds, motion_path)

    fields = dict.fromkeys(("text", "emotion", "speaker", "sentence_id"))
    extra: dict = {"layout": source.layout}
    meta_path = source.file("metadata")
    if meta_path is not None:
        meta = read_json_object(meta_path)
        fields = metadata_fields(meta, meta_path)
        fps = read_fps(meta, meta_path)
        if fps is not None and abs(fps - data.rate) > 1e-6 * fps:
            logger.warning("%s says %g fps, %s %g fps; using the motion file's", meta_path,
                           fps, motion_path.name, data.rate)
        if "variation" in meta:
            extra["variation"] = meta["variation"]
    text, phones, words = transcript_and_labels(source, audio_seconds)
    if text is not None:
        fields["text"] = text

    return RawClip(
        clip_id=source.clip_id, corpus=source.corpus, source=motion_path, motion=motion,
        fps=data.rate, schema=schema, audio=audio, sample_rate=sample_rate,
        checksum=checksum_files(source.paths), text=fields["text"], phones=phones,
        words=words,
        emotion=fields["emotion"], speaker=fields["speaker"],
        sentence_id=fields["sentence_id"], extra=extra,
    )
