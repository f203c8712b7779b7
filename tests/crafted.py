"""Crafted and damaged databases, crafted clips: the inputs of the security fuzz tests.

Shared by ``tests/test_fuzz.py`` and ``scripts/probe_security.py`` (which puts this
folder on ``sys.path``). Each database mutation takes a copy of a good database and
damages its live version in one way a careless or hostile sharer could.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from db.store import file_sha256

#: Bytes that drive a terminal: set its title (OSC 0, ended by BEL), clear the screen.
TERMINAL_ESCAPE = "\x1b]0;PWNED\x07\x1b[2J\u202eevil"


def _live(root: Path) -> Path:
    return root / (root / "CURRENT").read_text().strip()


def _first_part(folder: Path) -> Path:
    return sorted(folder.rglob("*.parquet"))[0]


def _rewrite(path: Path, change: Callable[[pa.Table], pa.Table]) -> None:
    table = pq.read_table(path, partitioning=None)
    pq.write_table(change(table), path)


def _set(name: str, row: int, value, type_=None):
    def change(t: pa.Table) -> pa.Table:
        values = t.column(name).to_pylist()
        values[row] = value
        i = t.column_names.index(name)
        return t.set_column(i, name, pa.array(values, type_ or t.schema.field(name).type))
    return change


def _replace_column(name: str, make):
    def change(t: pa.Table) -> pa.Table:
        i = t.column_names.index(name)
        return t.set_column(i, name, make(t))
    return change


def _animes(root: Path, change) -> None:
    _rewrite(_first_part(_live(root) / "animes"), change)


def _clips(root: Path, change) -> None:
    _rewrite(_first_part(_live(root) / "clips"), change)


def _audio(root: Path, change) -> None:
    _rewrite(_first_part(_live(root) / "audio"), change)


def edit_arrays(root: Path, change: Callable[[dict], dict], *, checksum: bool = True) -> None:
    """Change the model arrays; with ``checksum``, as a deliberate editor would, the
    manifest's checksum of them too (so that what is checked is the arrays)."""
    path = _live(root) / "model_arrays.parquet"
    t = pq.read_table(path)
    rows = {r["name"]: r for r in t.to_pylist()}
    rows = change(rows)
    names = sorted(rows)
    pq.write_table(pa.table({
        "name": pa.array(names, pa.string()),
        "shape": pa.array([rows[n]["shape"] for n in names], pa.list_(pa.int64())),
        "values": pa.array([rows[n]["values"] for n in names], pa.list_(pa.float64())),
    }), path)
    if checksum:
        refresh_checksum(root)


def refresh_checksum(root: Path) -> None:
    """Put the model arrays' file's SHA-256 in the manifest, as someone who edits the
    arrays on purpose would (so that what a test checks is the arrays, not the sum)."""
    path = _live(root) / "model_arrays.parquet"
    _manifest(root, lambda m: {**m, "checksums": {**m.get("checksums", {}),
                                                  "model_arrays": file_sha256(path)}})


def _array_edit(name: str, **fields):
    def change(rows: dict) -> dict:
        rows[name] = {**rows[name], **fields}
        return rows
    return change


def _drop_array(name: str):
    def change(rows: dict) -> dict:
        rows.pop(name)
        return rows
    return change


def _manifest(root: Path, edit: Callable[[dict], object]) -> None:
    path = _live(root) / "manifest.json"
    value = edit(json.loads(path.read_text()))
    path.write_text(value if isinstance(value, str) else json.dumps(value))


def _bytes(path_of: Callable[[Path], Path], data: Callable[[bytes], bytes]):
    def mutate(root: Path) -> None:
        path = path_of(root)
        path.write_bytes(data(path.read_bytes()))
    return mutate


def _first_list(values: list) -> int:
    """Index of the first list that is not null (a column may hold nulls: clips ingested
    without a phone model have no posteriors), else 0."""
    return next((k for k, v in enumerate(values) if v is not None), 0)


def _nan_list(t: pa.Table, name: str) -> pa.Array:
    values = t.column(name).to_pylist()
    k = _first_list(values)
    values[k] = [float("nan")] * len(values[k] or [0.0])
    return pa.array(values, t.schema.field(name).type)


def _short_list(t: pa.Table, name: str) -> pa.Array:
    """The first list one value short (a lone value where every one is null: a vector
    too short for any of the column's shapes)."""
    values = t.column(name).to_pylist()
    k = _first_list(values)
    values[k] = values[k][:-1] if values[k] is not None else [0.0]
    return pa.array(values, t.schema.field(name).type)


def _repeated_string(root: Path, name: str = "phoneme", length: int = 1 << 20) -> None:
    """The first ``animes`` part's column ``name`` one string of ``length`` bytes in every
    row, dictionary-encoded, as a writer without Arrow's schema stores it (read back as
    plain strings): a few KB more on disk, ``length`` bytes a row once read."""
    path = _first_part(_live(root) / "animes")
    t = pq.read_table(path, partitioning=None)
    one = pa.DictionaryArray.from_arrays(pa.array(np.zeros(t.num_rows, np.int32)),
                                         ["A" * length])
    pq.write_table(t.set_column(t.column_names.index(name), name, one), path,
                   compression="zstd", store_schema=False)


#: What a file outside a database holds, which no error about the database may print.
SECRET = "root:x:0:0:root:/root:/bin/bash"


def _current_elsewhere(root: Path, kind: str) -> None:
    """CURRENT replaced by a symbolic link to a file beside the database that holds
    :data:`SECRET` (its first bytes were printed in every command's error), or by a FIFO
    (opening it waited for a writer forever)."""
    current = root / "CURRENT"
    current.unlink()
    if kind == "symlink":
        secret = root.parent / f"{root.name}-secret.txt"
        secret.write_text(f"{SECRET}\n")
        current.symlink_to(secret)
    else:
        os.mkfifo(current)


#: name -> mutation of a database folder (the live version is damaged in place).
DATABASE_MUTATIONS: dict[str, Callable[[Path], None]] = {
    "current_binary": lambda r: (r / "CURRENT").write_bytes(b"\xff\xfe\x00\x9c" * 8),
    "current_huge": lambda r: (r / "CURRENT").write_bytes(b"v" * 10_000_000),
    "current_traversal": lambda r: (r / "CURRENT").write_text("../../etc"),
    "current_missing_version": lambda r: (r / "CURRENT").write_text("v999999"),
    "current_symlink": lambda r: _current_elsewhere(r, "symlink"),
    "current_fifo": lambda r: _current_elsewhere(r, "fifo"),
    "manifest_deep": lambda r: _manifest(r, lambda m: "[" * 100_000 + "]" * 100_000),
    "manifest_not_json": lambda r: _manifest(r, lambda m: "{not json"),
    "manifest_list": lambda r: _manifest(r, lambda m: [m]),
    "manifest_binary": _bytes(lambda r: _live(r) / "manifest.json", lambda b: b"\xff" + b[1:]),
    "manifest_fps_negative": lambda r: _manifest(r, lambda m: {**m, "fps": -30}),
    "manifest_fps_text": lambda r: _manifest(r, lambda m: {**m, "fps": "fast"}),
    "manifest_no_fps": lambda r: _manifest(r, lambda m: {k: v for k, v in m.items()
                                                       if k != "fps"}),
    "manifest_channels_wrong": lambda r: _manifest(r, lambda m: {**m, "n_channels": 3}),
    "manifest_schema": lambda r: _manifest(r, lambda m: {**m, "schema_version": 99}),
    "manifest_limits_text": lambda r: _manifest(r, lambda m: {**m, "limits": {
        "max_speed_mm_s": "fast"}}),
    # limits beyond any face: its clips (and the next ones) checked with nothing
    "manifest_limits_loose": lambda r: _manifest(r, lambda m: {**m, "limits": {
        "max_speed_mm_s": 1e30, "max_coordinate_mm": 1e30, "max_dropout_s": 1e30}}),
    "next_node_huge": lambda r: _animes(r, _set("next_node", 0, 10**9)),
    "next_node_negative": lambda r: _animes(r, _set("next_node", 0, -5)),
    "prev_node_huge": lambda r: _animes(r, _set("prev_node", 1, 2**40)),
    "next_node_wrong_clip": lambda r: _animes(r, _set("next_node", 0, 0)),
    "next_node_text": lambda r: _animes(r, _replace_column(
        "next_node", lambda t: pa.array([str(v) for v in t.column("next_node").to_pylist()]))),
    "node_id_duplicate": lambda r: _animes(r, _set("node_id", 1, 0)),
    "n_frames_zero": lambda r: _animes(r, _set("n_frames", 0, 0)),
    "n_frames_huge": lambda r: _animes(r, _set("n_frames", 0, 10**9)),
    "prosody_frames_negative": lambda r: _animes(r, _set("prosody_frames", 0, -3)),
    "start_after_end": lambda r: _animes(r, _set("start_frame", 0, 10**6)),
    "frame_overflow": lambda r: _animes(r, _set("end_frame", 0, 2**40)),
    "motion_nan": lambda r: _animes(r, _replace_column("motion",
                                                       lambda t: _nan_list(t, "motion"))),
    "motion_short": lambda r: _animes(r, _replace_column("motion",
                                                         lambda t: _short_list(t, "motion"))),
    "first_pcs_ragged": lambda r: _animes(r, _replace_column(
        "first_pcs", lambda t: _short_list(t, "first_pcs"))),
    "prosody_nan": lambda r: _animes(r, _replace_column("prosody",
                                                        lambda t: _nan_list(t, "prosody"))),
    "phoneme_unknown": lambda r: _animes(r, _set("phoneme", 0, "XYZ")),
    # What query --export puts in file names, divides by, counts or pairs up.
    "phoneme_path": lambda r: _animes(r, _set("phoneme", 0, "x/../../../../PWN")),
    # Labels read back when clips are added (prepared_from_database), as new clips' are.
    "clip_id_path": lambda r: _clips(r, _set("clip_id", 0, "../../../../tmp/PWN_CLIP")),
    "speaker_newline": lambda r: _clips(r, _set("speaker", 0, "a\nb")),
    # Terminal escapes (retitle the window, clear the screen) for info, sql and query.
    "speaker_escape": lambda r: _clips(r, _set("speaker", 0, TERMINAL_ESCAPE)),
    "corpus_escape": lambda r: _manifest(r, lambda m: {**m, "corpora": [
        TERMINAL_ESCAPE]}),
    "sentence_id_path": lambda r: _clips(r, _set("sentence_id", 0, "../../../etc")),
    "phoneme_nul": lambda r: _animes(r, _set("phoneme", 0, "A\x00A")),
    "start_time_inf": lambda r: _animes(r, _set("start_time", 0, float("inf"))),
    # A small file that decodes into far more (the rows check passes it).
    "phoneme_dictionary_huge": _repeated_string,
    "clip_fps_zero": lambda r: _clips(r, _set("fps", 0, 0.0)),
    "clip_fps_nan": lambda r: _clips(r, _set("fps", 0, float("nan"))),
    "clip_phones_mismatch": lambda r: _clips(r, _set("phones", 0, "AA B")),
    "audio_odd_bytes": lambda r: _audio(r, _set("pcm16", 0, b"\x01\x02\x03")),
    # A clip's lists that do not fit their frame counts (read when a baseline is fitted
    # on the database, or when clips are added to it).
    "clip_prosody_short": lambda r: _clips(r, _replace_column(
        "prosody", lambda t: _short_list(t, "prosody"))),
    "clip_posteriors_short": lambda r: _clips(r, _replace_column(
        "posteriors", lambda t: _short_list(t, "posteriors"))),
    "animes_column_missing": lambda r: _animes(r, lambda t: t.drop_columns(["next_node"])),
    "animes_truncated": _bytes(lambda r: _first_part(_live(r) / "animes"),
                               lambda b: b[: len(b) // 2]),
    "animes_random": _bytes(lambda r: _first_part(_live(r) / "animes"),
                            lambda b: np.random.default_rng(0).bytes(len(b))),
    "animes_empty": lambda r: [p.unlink() for p in (_live(r) / "animes").rglob("*.parquet")],
    "arrays_shape_mismatch": lambda r: edit_arrays(r, _array_edit("pca_components", shape=[999])),
    "arrays_shape_negative": lambda r: edit_arrays(r, _array_edit("channel_mean", shape=[-1])),
    "arrays_shape_deep": lambda r: edit_arrays(r, _array_edit("ica_mean", shape=[1] * 40)),
    "arrays_missing_pca": lambda r: edit_arrays(r, _drop_array("pca_components")),
    "arrays_missing_params": lambda r: edit_arrays(r, _drop_array("decomposer_params")),
    "arrays_nan_mixing": lambda r: edit_arrays(r, lambda rows: _array_edit(
        "ica_mixing", values=[float("nan")] * len(rows["ica_mixing"]["values"]))(rows)),
    "arrays_wrong_size_mixing": lambda r: edit_arrays(r, lambda rows: _array_edit(
        "ica_mixing", values=[1.0], shape=[1])(rows)),
    "arrays_zero_cutoffs": lambda r: edit_arrays(r, lambda rows: _array_edit(
        "ic_cutoff_hz", values=[0.0] * len(rows["ic_cutoff_hz"]["values"]))(rows)),
    "arrays_head_reference_shape": lambda r: edit_arrays(r, _array_edit(
        "head_reference", values=[1.0, 2.0], shape=[2])),
    # ica_mean zeroed is valid (the scores are centred): only the checksum tells.
    "arrays_checksum_stale": lambda r: edit_arrays(r, lambda rows: _array_edit(
        "ica_mean", values=[0.0] * len(rows["ica_mean"]["values"]))(rows), checksum=False),
    "arrays_checksum_wrong": lambda r: _manifest(r, lambda m: {**m, "checksums": "x"}),
    "arrays_random": _bytes(lambda r: _live(r) / "model_arrays.parquet",
                            lambda b: np.random.default_rng(1).bytes(len(b))),
    "channels_empty": lambda r: pq.write_table(
        pq.read_table(_live(r) / "channels.parquet").slice(0, 0), _live(r) / "channels.parquet"),
    "channels_no_name": lambda r: pq.write_table(
        pq.read_table(_live(r) / "channels.parquet").drop_columns(["name"]),
        _live(r) / "channels.parquet"),
    "components_missing": lambda r: (_live(r) / "components.parquet").unlink(),
    "frames_missing": lambda r: shutil.rmtree(_live(r) / "frames"),
    "hive_default_partition": lambda r: os.rename(
        sorted((_live(r) / "clips").iterdir())[0],
        _live(r) / "clips" / "emotion=__HIVE_DEFAULT_PARTITION__"),
    "symlink_out": lambda r: _symlink(_live(r) / "channels.parquet", "/etc/passwd"),
    # Damage no command checked (db.validate): a channel renamed in both its tables, values
    # out of their range, a flipped byte, names that are paths, a folder linked outside.
    "channel_renamed": lambda r: _rename_channel(r, "lip_corner_r.x", "lip_corner_r_x"),
    "clip_sample_rate_zero": lambda r: _clips(r, _set("sample_rate", 0, 0)),
    "clip_sample_rate_negative": lambda r: _clips(r, _set("sample_rate", 0, -16000)),
    "audio_sample_rate_zero": lambda r: _audio(r, _set("sample_rate", 0, 0)),
    "clip_duration_negative": lambda r: _clips(r, _set("duration", 0, -3.5)),
    "frames_nan": lambda r: _frames(r, _set("lip_corner_l.y", 5, float("nan"))),
    "frames_inf": lambda r: _frames(r, _set("lip_corner_l.y", 5, float("inf"))),
    "frame_negative": lambda r: _frames(r, _set("frame", 3, -7)),
    "frames_flipped_byte": lambda r: flip_page_byte(_first_part(_live(r) / "frames")),
    "manifest_kind_path": lambda r: _manifest(r, lambda m: {**m, "kind": "../../etc"}),
    "manifest_corpora_path": lambda r: _manifest(r, lambda m: {**m, "corpora": ["../x"]}),
    "manifest_tables_key_path": lambda r: _manifest(r, lambda m: {
        **m, "tables": {**m["tables"], "../../frames": 3}}),
    "frames_symlinked_out": lambda r: _move_out(_live(r) / "frames"),
    "components_cutoff_nan": lambda r: _rewrite(_live(r) / "components.parquet",
                                                _set("cutoff_hz", 0, float("nan"))),
    "clip_text_huge": lambda r: _rewrite_compressed(
        _first_part(_live(r) / "clips"), _set("text", 0, "x" * (3 << 20))),
}

#: Damage no command checked: each is refused by every reader of the table it is in, in
#: one line naming the database (db.validate).
UNCHECKED_DAMAGE = ("channel_renamed", "clip_sample_rate_zero", "clip_sample_rate_negative",
                    "audio_sample_rate_zero", "clip_duration_negative", "frames_nan",
                    "frames_inf", "frame_negative", "frames_flipped_byte",
                    "manifest_kind_path", "manifest_corpora_path",
                    "manifest_tables_key_path", "frames_symlinked_out",
                    "components_cutoff_nan", "clip_text_huge")
#: ... of which those that SQL (DuckDB scans, with no value read before) sees too: NaN is
#: in no Parquet statistics, so only a read of the values finds it.
SQL_SEES = tuple(m for m in UNCHECKED_DAMAGE if m not in ("frames_nan",
                                                          "components_cutoff_nan"))


def _frames(root: Path, change) -> None:
    _rewrite(_first_part(_live(root) / "frames"), change)


def _rename_channel(root: Path, old: str, new: str) -> None:
    """Channel ``old`` named ``new`` in the channels table and every frames file."""
    path = _live(root) / "channels.parquet"
    _rewrite(path, lambda t: t.set_column(t.column_names.index("name"), "name", pa.array(
        [new if n == old else n for n in t.column("name").to_pylist()])))
    for part in (_live(root) / "frames").rglob("*.parquet"):
        _rewrite(part, lambda t: t.rename_columns([new if n == old else n
                                                   for n in t.column_names]))


def _rewrite_compressed(path: Path, change) -> None:
    table = pq.read_table(path, partitioning=None)
    pq.write_table(change(table), path, compression="zstd")


def flip_page_byte(path: Path) -> None:
    """One bit of the Parquet file at ``path`` flipped in the middle of its first column
    chunk's data (a bad copy, a failing disk): the file still parses."""
    meta = pq.read_metadata(path)
    chunk = meta.row_group(0).column(meta.num_columns // 2)
    start = chunk.data_page_offset
    data = bytearray(path.read_bytes())
    data[start + chunk.total_compressed_size // 2] ^= 0x08
    path.write_bytes(bytes(data))


def _move_out(folder: Path) -> None:
    """``folder`` moved beside the database and linked back: read through the link."""
    root = folder.parent.parent
    outside = root.parent / f"{root.name}-outside-{folder.name}"
    shutil.rmtree(outside, ignore_errors=True)
    shutil.move(folder, outside)
    folder.symlink_to(outside, target_is_directory=True)


#: The ways :func:`corrupted` damages an array: ``negated`` (-|v| - 1), ``zeroed``, ``nan``
#: (its first value), ``huge`` (times 1e30), ``cut`` (its last column).
CORRUPTIONS = ("negated", "zeroed", "nan", "huge", "cut")


def corrupted(how: str):
    """A change of one array's row (:data:`CORRUPTIONS`); an empty array, or one without a
    second column to keep when cut, is left as it is."""
    def change(row: dict) -> dict:
        v = np.asarray(row["values"], dtype=np.float64)
        shape = list(row["shape"])
        if v.size == 0 or (how == "cut" and (not shape or shape[-1] < 2)):
            return row
        if how == "cut":
            v = v.reshape(shape)[..., :-1]
            shape[-1] -= 1
            return {**row, "shape": shape, "values": v.ravel().tolist()}
        if how == "nan":
            v = v.copy()
            v[0] = np.nan
        else:
            v = {"negated": -np.abs(v) - 1, "zeroed": np.zeros_like(v), "huge": v * 1e30}[how]
        return {**row, "values": v.tolist()}
    return change


def array_corrupted(name: str, how: str):
    """A change of the model arrays (:func:`edit_arrays`): array ``name`` :func:`corrupted`."""
    def change(rows: dict) -> dict:
        rows[name] = corrupted(how)(rows[name])
        return rows
    return change


#: array -> its corruptions that synthesis read silently before the arrays' invariants
#: were checked (ingest.invariants); each must now be refused.
ARRAY_CORRUPTIONS: dict[str, tuple[str, ...]] = {
    "channel_mean": ("negated", "zeroed", "huge"),
    "decomposer_params": ("negated", "zeroed", "huge"),
    "pca_components": ("negated", "zeroed", "huge"),
    "pca_explained_variance_ratio": ("negated", "zeroed", "huge", "cut"),
    "ica_unmixing": ("negated", "zeroed", "huge"),
    "ica_mixing": ("negated", "zeroed", "huge"),
    "ica_mean": ("negated", "huge"),
    "ic_cutoff_hz": ("huge",),
    "head_reference": ("zeroed",),
    "emotion/emotion_components": ("negated", "zeroed", "huge", "cut"),
    "emotion/centroid/angry": ("negated", "zeroed", "huge", "cut"),
    "emotion/offset/angry/happy": ("huge", "cut"),
    "emotion/map/angry/happy/centres": ("negated", "zeroed", "huge", "cut"),
    "emotion/map/angry/happy/targets": ("negated", "zeroed", "huge"),
    "emotion/map/angry/happy/coef": ("negated", "zeroed", "huge"),
    "emotion/map/angry/happy/offset": ("negated", "cut"),
    "emotion/map/angry/happy/params": ("negated", "zeroed"),
}
#: name -> mutation, as :data:`DATABASE_MUTATIONS`, one per :data:`ARRAY_CORRUPTIONS`.
ARRAY_MUTATIONS: dict[str, Callable[[Path], None]] = {
    f"{how}:{name}": (lambda r, name=name, how=how: edit_arrays(r, array_corrupted(name, how)))
    for name, hows in ARRAY_CORRUPTIONS.items() for how in hows
}


def _symlink(path: Path, target: str) -> None:
    path.unlink()
    path.symlink_to(target)


class PicklePayload:
    """Unpickling this creates the file ``marker``: proof that code from the data ran."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (Path.touch, (Path(self.marker),))


def crafted_database(good: Path, dest: Path, mutation: str) -> Path:
    """A copy of the database ``good`` at ``dest`` damaged by ``mutation``."""
    shutil.copytree(good, dest, symlinks=True)
    {**DATABASE_MUTATIONS, **ARRAY_MUTATIONS}[mutation](dest)
    return dest


def sql_escapes(version_dir: Path, root: Path, outside: Path) -> list[str]:
    """Statements that would write, reach outside the version, or undo the sandbox."""
    return [
        f"COPY (SELECT * FROM clips) TO '{outside}/stolen.csv'",
        f"EXPLAIN ANALYZE COPY (SELECT * FROM clips) TO '{outside}/stolen.csv'",
        f"explain analyse copy (select 1) to '{version_dir}/model_arrays.parquet'",
        f"EXPLAIN ANALYZE COPY (SELECT 1) TO '{root}/CURRENT'",
        f"EXPLAIN (FORMAT json) COPY (SELECT 1) TO '{outside}/stolen.json'",
        f"EXPORT DATABASE '{outside}/export'",
        f"IMPORT DATABASE '{outside}'",
        "EXPLAIN ANALYZE INSTALL httpfs", "INSTALL httpfs", "LOAD httpfs", "FORCE INSTALL x",
        f"ATTACH '{outside}/other.db' AS o", "DETACH memory",
        "SET enable_external_access = true", "SET allowed_directories = ['/']",
        "SET lock_configuration = false", "RESET lock_configuration",
        "PRAGMA enable_profiling", "CALL pragma_version()",
        "SELECT * FROM read_text('/etc/passwd')", "SELECT * FROM read_csv('/etc/passwd')",
        "SELECT * FROM read_csv_auto('/etc/passwd')", "SELECT * FROM read_blob('/etc/passwd')",
        "SELECT * FROM read_json('/etc/passwd')", "SELECT * FROM glob('/etc/*')",
        "SELECT * FROM glob('/root/**')", "SELECT * FROM '/etc/passwd'",
        f"SELECT * FROM read_text('{version_dir}/../../outside.txt')",
        f"SELECT * FROM read_text('{outside}/outside.txt')",
        f"SELECT * FROM glob('{root}/*')",
        "SELECT * FROM read_parquet('https://example.com/x.parquet')",
        "SELECT * FROM read_parquet('s3://bucket/x.parquet')",
        "SELECT 1; CREATE TABLE t AS SELECT 1", "SELECT 1; DROP VIEW clips",
        "CREATE MACRO m() AS 1", "CREATE SECRET s (TYPE s3)", "INSERT INTO clips VALUES (1)",
        "UPDATE clips SET emotion = 'x'", "DELETE FROM clips", "CHECKPOINT", "VACUUM",
        "BEGIN TRANSACTION", "USE memory", "SELECT getenv('HOME')",
    ]


def sql_bombs() -> dict[str, str]:
    """Reading statements that would take the machine's memory, disk or time unless the
    sandbox bounds them (memory and spill caps, the timer, DuckDB's depth limit)."""
    return {
        "string_agg of 6 GB": "SELECT length(string_agg(repeat('x', 100000), '')) "
                              "FROM range(60000)",
        "GROUP BY of 10^9 groups": "SELECT count(*) FROM (SELECT range % 1000000000 AS g, "
                                   "count(*) FROM range(2000000000) GROUP BY g)",
        "list of 3*10^9 numbers": "SELECT max(len(l)) FROM (SELECT list(range) AS l "
                                  "FROM range(3000000000))",
        "recursive CTE of 10^9 rows": "WITH RECURSIVE t(n) AS (SELECT 1 UNION ALL SELECT "
                                      "n + 1 FROM t WHERE n < 1000000000) SELECT count(*) "
                                      "FROM t",
        "10^12-row count": "SELECT count(*) FROM range(1000000000000)",
        "5,000 nested brackets": "SELECT " + "(" * 5000 + "1" + ")" * 5000,
    }


# --------------------------------------------------------------------------- media files


def disguised_playlists(target: Path) -> dict[str, str]:
    """Text files that make ffmpeg open ``target`` (a local video), by kind.

    Named like a video (``speech.mp4``), each is a playlist or manifest: ffmpeg picks a
    demuxer by content, and these demuxers open the files they list. ``target`` is named
    by an absolute ``file://`` URL (DASH, HLS), an absolute path, and a path relative to
    the playlist (concat: a neighbour of the playlist, or a file a symlink there points to).
    """
    uri = Path(target).absolute().as_uri()
    return {
        "dash": (
            '<?xml version="1.0"?>\n<MPD xmlns="urn:mpeg:dash:schema:mpd:2011" '
            'profiles="urn:mpeg:dash:profile:isoff-on-demand:2011" type="static" '
            'mediaPresentationDuration="PT2S" minBufferTime="PT1S"><Period>'
            '<AdaptationSet mimeType="video/mp4"><Representation id="v" bandwidth="1000">'
            f"<BaseURL>{uri}</BaseURL></Representation></AdaptationSet></Period></MPD>\n"),
        "hls": f"#EXTM3U\n#EXT-X-TARGETDURATION:2\n#EXTINF:2.0,\n{uri}\n#EXT-X-ENDLIST\n",
        "concat": f"ffconcat version 1.0\nfile '{Path(target).absolute()}'\n",
        "concat-relative": f"ffconcat version 1.0\nfile '{Path(target).name}'\n",
    }


def flac_declaring(path: Path, n_samples: int) -> Path:
    """A second of FLAC (named as the caller likes: libsndfile reads by content) whose
    header declares ``n_samples`` (at most 2**36 - 1): the length decoders allocate for."""
    import soundfile

    soundfile.write(str(path), np.zeros(16000, np.float32), 16000, format="FLAC")
    data = bytearray(path.read_bytes())
    # STREAMINFO follows "fLaC" and its 4-byte block header; bytes 10..17 of it hold the
    # rate (20 bits), channels (3), bits per sample (5) and the total samples (36)
    fields = int.from_bytes(data[18:26], "big")
    fields = (fields >> 36 << 36) | n_samples
    data[18:26] = fields.to_bytes(8, "big")
    path.write_bytes(data)
    return path


def quad_bin() -> bytes:
    """The buffer of :func:`gltf_reaching`'s quad."""
    return (np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 1]], np.float32).tobytes()
            + np.array([0, 1, 2, 0, 2, 3], np.uint32).tobytes())


def gltf_drawing(uri: str, n_nodes: int, *, nested: bool) -> dict:
    """:func:`gltf_reaching`'s quad drawn by ``n_nodes`` nodes, each the child of the one
    before (``nested``: trimesh walks every node's chain of parents) or all children of
    the first: a few hundred bytes a node, the quad's vertices a node."""
    gltf = gltf_reaching(uri)
    gltf["nodes"] = ([{"mesh": 0, "children": [i + 1]} for i in range(n_nodes - 1)]
                     if nested else [{"mesh": 0, "children": list(range(1, n_nodes))}]
                     ) + [{"mesh": 0}] * (1 if nested else n_nodes - 1)
    return gltf


def gltf_reaching(uri: str) -> dict:
    """A one-quad glTF whose buffer is the file at ``uri`` (48 bytes of float32
    positions, 24 of uint32 indices): trimesh before 5.0 read it wherever it was."""
    return {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"uri": uri, "byteLength": 72}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                        {"buffer": 0, "byteOffset": 48, "byteLength": 24}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 1]},
                      {"bufferView": 1, "componentType": 5125, "count": 6, "type": "SCALAR"}],
    }
