"""The versioned Parquet store and its read-only SQL layer."""

from __future__ import annotations

import os

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from db.errors import DataError, ParameterError
from db.sql import check_read_only, query
from db.store import (
    TABLES,
    Database,
    arrays_from_table,
    arrays_to_table,
    current_version,
    write_version,
)


def _tables(n_clips=2, tag="a"):
    emotions = ["happy", "sad"][:n_clips]
    clips = pa.table({"clip_id": [f"{tag}{i}" for i in range(n_clips)], "emotion": emotions})
    animes = pa.table({"node_id": pa.array(range(2 * n_clips), pa.int64()),
                       "clip_id": [f"{tag}{i // 2}" for i in range(2 * n_clips)],
                       "phoneme": ["AA", "B"] * n_clips,
                       "emotion": [emotions[i // 2] for i in range(2 * n_clips)]})
    frames = pa.table({"clip_id": [f"{tag}0"] * 3, "emotion": ["happy"] * 3,
                       "frame": pa.array([0, 1, 2], pa.int32()),
                       "jaw": pa.array([0.1, 0.2, 0.3], pa.float32())})
    return {
        "clips": clips, "animes": animes, "frames": frames,
        "audio": pa.table({"clip_id": [f"{tag}0"], "pcm16": [b"\x00\x01"]}),
        "channels": pa.table({"channel": [0], "name": ["jaw"]}),
        "model_arrays": arrays_to_table({"m": np.arange(6.0).reshape(2, 3)}),
        "components": pa.table({"component": [0], "cutoff_hz": [3.5]}),
    }


def test_write_then_read_every_table(tmp_path):
    write_version(tmp_path / "db", _tables(), {"fps": 30.0})
    db = Database.open(tmp_path / "db")
    assert db.manifest["fps"] == 30.0 and db.manifest["db_version"] == 1
    for name in TABLES:
        assert db.table(name).num_rows == _tables()[name].num_rows
    # Partitioned by emotion, hive style, readable by a plain Parquet reader.
    assert (db.version_dir / "animes" / "emotion=happy").is_dir()
    assert pq.read_table(db.version_dir / "channels.parquet").num_rows == 1
    np.testing.assert_array_equal(db.arrays()["m"], np.arange(6.0).reshape(2, 3))


def test_a_table_built_clip_by_clip_is_written_in_few_row_groups(tmp_path, monkeypatch):
    """Frames concatenated from one small table a clip are gathered into row groups of
    about ROW_GROUP_BYTES (one a clip made wide tables expensive to read), in order."""
    import db.store as store

    rng = np.random.default_rng(0)
    parts = [pa.table({"clip_id": [f"c{k:03d}"] * 10, "emotion": ["neutral"] * 10,
                       "frame": pa.array(np.arange(10), pa.int32()),
                       **{f"ch{c}": pa.array(rng.normal(size=10).astype(np.float32))
                          for c in range(50)}}) for k in range(120)]
    frames = pa.concat_tables(parts)
    assert frames.column("ch0").num_chunks == 120
    monkeypatch.setattr(store, "ROW_GROUP_BYTES", 40_000)
    monkeypatch.setattr(store, "MIN_GROUP_ROWS", 1)
    rows = store.rows_per_group(frames)
    assert rows == 40_000 // (frames.nbytes / frames.num_rows)
    channels = pa.table({"channel": pa.array(range(50), pa.int32()),
                         "name": [f"ch{c}" for c in range(50)]})
    write_version(tmp_path / "db", {**_tables(), "frames": frames, "channels": channels},
                  {"fps": 30.0})
    db = Database.open(tmp_path / "db")
    files = list(db.table_path("frames").rglob("*.parquet"))
    meta = pq.ParquetFile(files[0]).metadata
    assert len(files) == 1 and meta.num_row_groups == -(-1200 // rows)
    assert max(meta.row_group(i).num_rows for i in range(meta.num_row_groups)) == rows
    back = db.table("frames")
    assert back.column("clip_id").to_pylist() == frames.column("clip_id").to_pylist()
    np.testing.assert_array_equal(back.column("ch7").to_numpy(), frames.column("ch7").to_numpy())


def test_floats_are_written_without_a_dictionary(tmp_path):
    """Motion values hardly repeat: a dictionary would be tried and given up page by page
    (slower and larger); names and ids keep theirs. The values read back unchanged."""
    write_version(tmp_path / "db", _tables(), {"fps": 30.0})
    db = Database.open(tmp_path / "db")
    (frames,) = db.table_path("frames").rglob("*.parquet")
    meta = pq.ParquetFile(frames).metadata.row_group(0)
    encodings = {meta.column(i).path_in_schema: meta.column(i).encodings
                 for i in range(meta.num_columns)}
    assert not any("DICTIONARY" in e for e in encodings["jaw"]), encodings
    assert any("DICTIONARY" in e for e in encodings["clip_id"]), encodings
    assert db.table("frames").column("jaw").to_pylist() == pytest.approx([0.1, 0.2, 0.3])
    (arrays,) = db.version_dir.glob("model_arrays.parquet")
    meta = pq.ParquetFile(arrays).metadata.row_group(0)
    values = [meta.column(i) for i in range(meta.num_columns)
              if meta.column(i).path_in_schema.startswith("values")]
    assert values and not any("DICTIONARY" in e for c in values for e in c.encodings)


def test_model_arrays_round_trip_exactly():
    rng = np.random.default_rng(0)
    arrays = {"a": rng.normal(size=(4, 5)), "b": rng.normal(size=7), "c": np.zeros((0, 3))}
    back = arrays_from_table(arrays_to_table(arrays))
    for k in arrays:
        np.testing.assert_array_equal(back[k], arrays[k])


def test_new_version_replaces_old_and_keeps_one_behind(tmp_path):
    root = tmp_path / "db"
    for tag in "abc":
        write_version(root, _tables(tag=tag), {"fps": 30.0})
    assert current_version(root) == "v000003"
    assert sorted(p.name for p in root.iterdir() if p.name.startswith("v")) == [
        "v000002", "v000003"]
    assert Database.open(root).table("clips").column("clip_id").to_pylist()[0] == "c0"


def test_emotions_differing_only_in_case_are_refused(tmp_path):
    """They would name one partition folder on macOS and Windows, one overwriting the
    other's part files: the write is refused and the database left as it was."""
    root = tmp_path / "db"
    write_version(root, _tables(tag="a"), {"fps": 30.0})
    before = sorted(os.listdir(root))
    tables = _tables(tag="b")
    tables["clips"] = pa.table({"clip_id": ["b0", "b1"], "emotion": ["happy", "Happy"]})
    with pytest.raises(DataError, match="'happy' and 'Happy' differ only in case"):
        write_version(root, tables, {"fps": 30.0})
    assert sorted(os.listdir(root)) == before


def test_failed_write_leaves_the_database_as_it_was(tmp_path, monkeypatch):
    import db.store as store

    root = tmp_path / "db"
    write_version(root, _tables(tag="a"), {"fps": 30.0})
    before = sorted(os.listdir(root))
    real = store._write_table

    def dies_on_audio(folder, name, table):  # as if killed half-way through the tables
        if name == "audio":
            raise KeyboardInterrupt
        real(folder, name, table)

    monkeypatch.setattr(store, "_write_table", dies_on_audio)
    with pytest.raises(KeyboardInterrupt):
        write_version(root, _tables(tag="b"), {"fps": 30.0})
    assert sorted(os.listdir(root)) == before
    assert Database.open(root).table("clips").column("clip_id").to_pylist() == ["a0", "a1"]
    broken = _tables(tag="c")
    broken["animes"] = pa.table({"node_id": [1]})  # nothing to partition by
    with pytest.raises(ValueError, match="emotion"):
        write_version(root, broken, {"fps": 30.0})
    assert sorted(os.listdir(root)) == before


def test_not_a_database(tmp_path):
    with pytest.raises(DataError, match="does not exist"):
        Database.open(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataError, match="not an animegraph database"):
        Database.open(tmp_path / "empty")
    (tmp_path / "empty" / "CURRENT").write_text("v000009")
    with pytest.raises(DataError, match="damaged"):
        Database.open(tmp_path / "empty")


def test_sql_reads_the_views(tmp_path):
    write_version(tmp_path / "db", _tables(), {"fps": 30.0})
    db = Database.open(tmp_path / "db")
    out = query(db, "SELECT emotion, count(*) AS n FROM animes GROUP BY 1 ORDER BY 1")
    assert out.to_pylist() == [{"emotion": "happy", "n": 2}, {"emotion": "sad", "n": 2}]
    out = query(db, "SELECT avg(jaw) AS m FROM frames")
    assert out.column("m")[0].as_py() == pytest.approx(0.2)


@pytest.mark.parametrize("sql", [
    "COPY (SELECT 1) TO 'x.csv'", "CREATE TABLE t(a INT)", "INSERT INTO clips VALUES (1)",
    "ATTACH 'other.db'", "SET threads = 1", "INSTALL httpfs", "SELECT 1; DROP VIEW clips",
])
def test_sql_refuses_writes(sql):
    with pytest.raises(ParameterError, match="only SELECT"):
        check_read_only(sql)


def test_sql_errors_are_one_line(tmp_path):
    write_version(tmp_path / "db", _tables(), {"fps": 30.0})
    db = Database.open(tmp_path / "db")
    with pytest.raises(ParameterError) as err:
        query(db, "SELECT no_such_column FROM animes")
    assert "\n" not in str(err.value)
    with pytest.raises(ParameterError, match="parse"):
        check_read_only("SELEC 1")


def _footer_bomb(path, rows=2_000_000):
    """Replace the Parquet file at ``path`` with a small one whose footer declares
    ``rows`` rows: one dictionary-encoded string, run-length encoded (a few KB on disk,
    about 10 MB once decoded; the crafted ones decode into gigabytes)."""
    phoneme = pa.DictionaryArray.from_arrays(pa.array(np.zeros(rows, np.int8)), ["AA"])
    pq.write_table(pa.table({"phoneme": phoneme}), path, use_dictionary=True,
                   compression="zstd", row_group_size=rows)
    assert path.stat().st_size < rows // 100


def test_a_footer_declaring_more_rows_than_the_manifest_is_refused_unread(
        tmp_path, monkeypatch):
    import json

    from db.sql import run

    write_version(tmp_path / "db", _tables(), {"fps": 30.0})
    db = Database.open(tmp_path / "db")
    part = db.version_dir / "animes" / "emotion=happy" / "part-0.parquet"
    _footer_bomb(part)

    def no_reading(*args, **kwargs):
        raise AssertionError("the table's data was read")

    monkeypatch.setattr(pq.ParquetFile, "read", no_reading)
    monkeypatch.setattr(pq.ParquetFile, "iter_batches", no_reading)
    for how in ({}, {"columns": ["phoneme"]}, {"filter": pa.compute.field("phoneme") == "AA"}):
        with pytest.raises(DataError) as err:
            db.table("animes", **how)
        message = str(err.value)
        assert "\n" not in message and message.startswith(f"database {db.root} is damaged: ")
        assert "animes" in message and "2000002 rows, the manifest 4" in message
    with pytest.raises(DataError, match=r"animes: its files' footers declare 2000002 rows"):
        run(db, "SELECT count(*) FROM clips")  # DuckDB's views are refused before a scan
    monkeypatch.undo()
    assert db.table("clips").num_rows == 2  # the other tables read as before

    # A manifest edited to match the footer (or without counts): the footer is still
    # implausible for a file of its size.
    manifest = json.loads((db.version_dir / "manifest.json").read_text())
    for counts in ({**manifest["tables"], "animes": 2_000_002}, None):
        edited = {**manifest, "tables": counts}
        (db.version_dir / "manifest.json").write_text(json.dumps(edited))
        with pytest.raises(DataError, match=r"emotion=happy/part-0.parquet declares 2000000 "
                                             r"rows in \d+ bytes, more than 1 a byte"):
            Database.open(tmp_path / "db").table("animes")


def _string_bomb(path, encoding, rows=2, length=4 << 20):
    """Replace the Parquet file at ``path`` with ``rows`` rows whose ``phoneme`` is one
    string of ``length`` bytes, as a writer without Arrow's schema stores it: a few KB
    on disk (zstd), ``rows * length`` bytes once read."""
    if encoding == "dictionary":  # one value in the dictionary page, every row its index
        phoneme = pa.DictionaryArray.from_arrays(pa.array([0] * rows, pa.int32()),
                                                 ["A" * length])
        options = {"use_dictionary": True}
    else:
        phoneme = pa.array(["A" * length] * rows)
        options = {"use_dictionary": False,
                   **({"column_encoding": {"phoneme": "DELTA_BYTE_ARRAY"}}
                      if encoding == "delta" else {})}
    pq.write_table(pa.table({"phoneme": phoneme}), path, compression="zstd",
                   store_schema=False, **options)
    assert path.stat().st_size < length // 100


@pytest.mark.parametrize("encoding", ["dictionary", "plain", "delta"])
def test_a_small_file_decoding_to_far_more_is_refused_unread(tmp_path, encoding):
    """A string repeated by a dictionary (or by delta encoding, or compressed a
    thousandfold) passed the rows check: 2,106 rows of one 8 MB string in a 2 MB
    ``animes`` file made info, sql, query and synth allocate 17 GB."""
    from db.sql import run

    write_version(tmp_path / "db", _tables(), {"fps": 30.0})
    db = Database.open(tmp_path / "db")
    part = db.version_dir / "animes" / "emotion=happy" / "part-0.parquet"
    _string_bomb(part, encoding)
    refused = (r"animes: emotion=happy/part-0.parquet decodes to up to \d+ bytes from "
               r"\d+, more than 64 times its size: a crafted file \(not read\)")
    for how in ({}, {"filter": pa.compute.field("phoneme") == "AA"}):
        with pytest.raises(DataError, match=refused):
            db.table("animes", **how)
    with pytest.raises(DataError, match=refused):
        run(db, "SELECT count(*) FROM clips")
    assert db.table("clips").num_rows == 2  # the other tables read as before


def test_long_distinct_strings_in_a_dictionary_are_read(tmp_path):
    # Each clip's speech is one long value, which this version writes without a
    # dictionary; in one (as earlier versions wrote it) the footer's bound, every row as
    # long as the whole dictionary page, is far too high: the values are counted.
    tables = _tables(n_clips=2)
    pcm = [np.random.default_rng(i).bytes(1 << 17) for i in range(100)]
    tables["audio"] = pa.table({"clip_id": [f"a{i}" for i in range(100)], "pcm16": pcm})
    write_version(tmp_path / "db", tables, {"fps": 30.0})
    [part] = (tmp_path / "db").glob("v*/audio/part-0.parquet")
    assert "RLE_DICTIONARY" not in pq.read_metadata(part).row_group(0).column(1).encodings
    pq.write_table(tables["audio"], part, use_dictionary=True)
    chunk = pq.read_metadata(part).row_group(0).column(1)
    assert "RLE_DICTIONARY" in chunk.encodings
    assert 100 * chunk.total_uncompressed_size > 64 * part.stat().st_size
    assert Database.open(tmp_path / "db").table("audio").column("pcm16").to_pylist() == pcm


def test_a_new_version_of_model_arrays_links_the_rest_and_fails_whole(tmp_path, monkeypatch):
    """write_model_arrays (a classifier stored by 'emotion fit --db'): a new version with
    the other tables' files linked, atomic, refused if the database moved on."""
    import db.store as store
    from db.store import write_model_arrays

    root = tmp_path / "db"
    write_version(root, _tables(), {"fps": 30.0})
    db = Database.open(root)
    before = current_version(root)
    new = write_model_arrays(root, {"m": np.ones((2, 2))}, {**db.manifest, "note": "x"},
                             based_on=before)
    db2 = Database.open(root)
    assert db2.version_dir == new and db2.manifest["note"] == "x"
    np.testing.assert_array_equal(db2.arrays()["m"], np.ones((2, 2)))
    assert db2.table("clips").num_rows == 2 and db2.manifest["db_version"] == 2
    assert (new / "channels.parquet").stat().st_ino == \
        (root / before / "channels.parquet").stat().st_ino  # linked, not copied
    with pytest.raises(DataError, match="changed while this write was prepared"):
        write_model_arrays(root, {"m": np.zeros(1)}, db2.manifest, based_on=before)

    def broken(folder, name, table):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(store, "_write_table", broken)
    with pytest.raises(OSError):
        write_model_arrays(root, {"m": np.zeros(1)}, db2.manifest, based_on=new.name)
    assert current_version(root) == new.name
    assert not [p for p in root.iterdir() if ".partial-" in p.name]  # no staging left
    np.testing.assert_array_equal(Database.open(root).arrays()["m"], np.ones((2, 2)))


def _aged(path, seconds=3600):
    """Set the file's modification time back: a later change in place (even within one
    tick of the kernel's clock) then changes it."""
    past = os.stat(path).st_mtime_ns - seconds * 10**9
    os.utime(path, ns=(past, past))


@pytest.fixture
def remembered(monkeypatch):
    """Checks remembered at once (db.memo.SETTLE_NS 0), from an empty memo."""
    import db.memo
    import db.store

    monkeypatch.setattr(db.memo, "SETTLE_NS", 0)
    db.store._CHECKED.clear()
    db.store._ARRAYS.clear()
    yield
    db.store._CHECKED.clear()
    db.store._ARRAYS.clear()


def test_arrays_and_footers_are_checked_once_per_process(tmp_path, monkeypatch, remembered):
    """Every Database of one version shares the checks of its files: the model arrays are
    hashed and read once, each table's footers checked once; the arrays are read-only."""
    import db.store

    write_version(tmp_path / "db", _tables(), {"fps": 30.0})
    hashed, footers = [], []
    real_hash, real_check = db.store.file_sha256, Database._check_footers
    monkeypatch.setattr(db.store, "file_sha256", lambda p: hashed.append(p) or real_hash(p))
    monkeypatch.setattr(Database, "_check_footers", lambda self, name, files:
                        footers.append(name) or real_check(self, name, files))
    for _ in range(3):
        db = Database.open(tmp_path / "db")
        arrays = db.arrays()
        db.table("frames")
    assert len(hashed) == 1 and footers.count("frames") == 1
    assert footers.count("model_arrays") == 1
    np.testing.assert_array_equal(arrays["m"], np.arange(6.0).reshape(2, 3))
    with pytest.raises(ValueError, match="read-only"):
        arrays["m"][0, 0] = 1.0


def test_a_file_changed_after_its_check_is_checked_again(tmp_path, remembered):
    """A remembered check holds only for the file as it was: one damaged in place (same
    size, same inode) or swapped for another version's is refused at the next read."""
    write_version(tmp_path / "db", _tables(), {"fps": 30.0})
    db = Database.open(tmp_path / "db")
    arrays_file = db.table_path("model_arrays")
    _aged(arrays_file)
    db.arrays()  # remembered
    data = bytearray(arrays_file.read_bytes())
    data[len(data) // 2] ^= 0xFF
    arrays_file.write_bytes(bytes(data))
    with pytest.raises(DataError, match="SHA-256"):
        Database.open(tmp_path / "db").arrays()
    # Swapped: the file of another database (its own checksum differs).
    write_version(tmp_path / "other", {**_tables(), "model_arrays": arrays_to_table(
        {"m": np.ones((2, 3))})}, {"fps": 30.0})
    os.replace(Database.open(tmp_path / "other").table_path("model_arrays"), arrays_file)
    with pytest.raises(DataError, match="SHA-256"):
        Database.open(tmp_path / "db").arrays()


def test_a_footer_changed_after_its_check_is_checked_again(tmp_path, remembered):
    """A table whose file is replaced by one declaring other rows is refused although
    its footers were checked before."""
    write_version(tmp_path / "db", _tables(), {"fps": 30.0})
    db = Database.open(tmp_path / "db")
    channels = db.table_path("channels")
    _aged(channels)
    db.table("channels")  # remembered
    pq.write_table(pa.table({"channel": [0, 1], "name": ["jaw", "lip"]}), channels)
    with pytest.raises(DataError, match="declare 2 rows"):
        Database.open(tmp_path / "db").table("channels")


def test_a_file_just_written_is_not_remembered(tmp_path, monkeypatch):
    """A check of a file changed less than db.memo.SETTLE_NS ago is not remembered: two
    changes within one tick of the kernel's clock leave its times as they were."""
    import db.store

    write_version(tmp_path / "db", _tables(), {"fps": 30.0})
    db.store._ARRAYS.clear()
    db = Database.open(tmp_path / "db")
    db.arrays()
    arrays_file = db.table_path("model_arrays")
    stat = os.stat(arrays_file)
    data = bytearray(arrays_file.read_bytes())
    data[len(data) // 2] ^= 0xFF
    arrays_file.write_bytes(bytes(data))
    os.utime(arrays_file, ns=(stat.st_atime_ns, stat.st_mtime_ns))  # as if in one tick
    with pytest.raises(DataError, match="SHA-256"):
        Database.open(tmp_path / "db").arrays()


@pytest.mark.parametrize("dictionary", [True, False])
def test_strings_are_counted_and_measured_as_read_without_decoding_each_row(tmp_path,
                                                                            dictionary):
    """decoded_bytes counts a dictionary's strings once a row they are in, exactly as the
    rows decoded would give; check_text finds one long value among many rows."""
    from db.footers import decoded_bytes
    from db.validate import MAX_TEXT_BYTES, check_text

    rng = np.random.default_rng(0)
    words = ["x" * int(n) for n in rng.integers(0, 3000, size=40)] + [None]
    column = [words[i] for i in rng.integers(0, len(words), size=5000)]
    path = tmp_path / "t.parquet"
    pq.write_table(pa.table({"s": column}), path, use_dictionary=dictionary,
                   row_group_size=700)
    meta = pq.read_metadata(path)
    exact = sum(len(s) for s in column if s is not None)
    base = sum(meta.row_group(g).column(0).total_uncompressed_size
               + 4 * meta.row_group(g).column(0).num_values
               for g in range(meta.num_row_groups))
    if dictionary:  # the bound (each row as long as its chunk) passes the limit: counted
        assert decoded_bytes(path, meta, 0, base + exact) == base + exact
    column[4321] = "y" * (MAX_TEXT_BYTES + 1)
    pq.write_table(pa.table({"s": column}), path, use_dictionary=dictionary,
                   row_group_size=700)

    class Db:
        def damaged(self, name, problem):
            return DataError(f"{name}: {problem}")

    with pytest.raises(DataError, match=f"a s value of {MAX_TEXT_BYTES + 1} bytes"):
        check_text(Db(), "t", path, "t.parquet", pq.read_metadata(path))
