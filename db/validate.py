"""What a database must hold before anything reads it: the one validation layer of
:class:`db.store.Database`.

A database is shared between people, so every command (``info``, ``sql``, ``query``,
``classify``, ``synth``, ``ingest`` adding to one ...) reads it through
:class:`~db.store.Database`, which checks it here, cheaply, in three places:

1. **When it is opened** (:func:`check_opened`): the manifest's names (``kind``,
   ``corpora``, the keys of ``tables`` and ``checksums``) are plain names, never paths;
   no file or folder of the version is a symbolic link leaving the database folder
   (one would be followed silently, e.g. a ``frames`` folder linked to someone else's);
   the ``channels`` table (:func:`check_channels`) is a schema the motion can be read
   with (unique names, one kind, a point's coordinates as ``.x``, ``.y``, ``.z`` in
   order, every channel a column of ``frames``).
   Then every table's footers' statistics (:func:`check_statistics`: min and max of a
   row group, written by every Parquet writer) of the columns in :data:`RULES`, with no
   value read: a sample rate of 0, a negative duration or frame number, an infinite
   coordinate.
2. **Before a table's files are read** (:func:`check_text`, from
   :meth:`~db.store.Database.check_rows`, after its bound of the decoded bytes): no
   text value longer than :data:`MAX_TEXT_BYTES` (from the column chunks' uncompressed
   sizes; a chunk that could hold one is decoded a few rows at a time).
3. **When a table is read** (:func:`check_values`): the same rules on the values read,
   which also sees NaN (Parquet's statistics leave NaN out).

Flipped bytes are caught by Parquet's page checksums (CRC-32 of every page), which this
version writes (:data:`WRITE_OPTIONS`) and every read verifies (:data:`READ_OPTIONS`);
files written before carry none and are read unverified.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from db.arrow import numbers

#: A value's lowest bound: ``(bound, strict)``; NaN and infinity are refused by every rule.
POSITIVE = (0.0, True)
NON_NEGATIVE = (0.0, False)
FINITE = (-math.inf, False)
#: table -> column -> bound its values keep (nulls are allowed: "not known").
#: ``"*"`` stands for every floating-point column of the table (the motion channels).
RULES: dict[str, dict[str, tuple[float, bool]]] = {
    "clips": {"fps": POSITIVE, "source_fps": POSITIVE, "sample_rate": POSITIVE,
              "duration": NON_NEGATIVE, "n_frames": NON_NEGATIVE, "n_animes": NON_NEGATIVE,
              "prosody_frames": NON_NEGATIVE, "posterior_frames": NON_NEGATIVE},
    "animes": {"position": NON_NEGATIVE, "start_time": NON_NEGATIVE,
               "end_time": NON_NEGATIVE, "start_frame": NON_NEGATIVE,
               "end_frame": NON_NEGATIVE, "n_frames": NON_NEGATIVE,
               "prosody_frames": NON_NEGATIVE},
    "frames": {"frame": NON_NEGATIVE, "time": NON_NEGATIVE, "*": FINITE},
    "audio": {"sample_rate": POSITIVE},
    "channels": {"channel": NON_NEGATIVE, "min": FINITE, "max": FINITE},
    "components": {"component": NON_NEGATIVE, "cutoff_hz": POSITIVE,
                   "motion_share": NON_NEGATIVE},
}
#: Longest text value, bytes (a transcript, a clip's phones, a path): a crafted 300 MB
#: string in a 14 MB file passed the per-byte size guard and kept ``query`` 59 s and
#: 3.4 GB busy. The longest this version writes are a clip's phones (a few KB).
MAX_TEXT_BYTES = 1 << 20
#: Most bytes of a name the manifest holds (a corpus, the motion's kind).
MAX_NAME_BYTES = 255
#: Parquet options: pages written with their CRC-32, and verified when read.
WRITE_OPTIONS = {"write_page_checksum": True}
READ_OPTIONS = {"page_checksum_verification": True}
#: Kinds of motion whose channels are points' coordinates.
POINT_KINDS = ("markers", "landmarks")


def plain_name(value) -> bool:
    """True if ``value`` is a name that is no path: a non-empty printable string of at
    most :data:`MAX_NAME_BYTES` bytes, without ``/`` or ``\\``, not ``.`` or ``..``."""
    return (isinstance(value, str) and value not in ("", ".", "..")
            and len(value.encode("utf-8", "replace")) <= MAX_NAME_BYTES
            and value.isprintable() and "/" not in value and "\\" not in value)


def check_manifest(manifest: dict, tables: tuple[str, ...], damaged) -> None:
    """``damaged(problem)`` (a DataError) unless the names the manifest holds are plain
    names (:func:`plain_name`) and its ``tables``/``checksums`` keys are tables."""
    kind = manifest.get("kind")
    if kind is not None and not plain_name(kind):
        raise damaged(f"kind is {_shown(kind)}, not a plain name")
    corpora = manifest.get("corpora")
    if corpora is not None:
        if not isinstance(corpora, list):
            raise damaged(f"corpora is {_shown(corpora)}, not a list")
        bad = next((c for c in corpora if not plain_name(c)), None)
        if bad is not None:
            raise damaged(f"corpus {_shown(bad)} is not a plain name")
    for key in ("tables", "checksums"):
        value = manifest.get(key)
        if value is None or (key == "checksums" and isinstance(value, str)):
            continue  # a checksum that is no mapping is the model arrays' check's to say
        if not isinstance(value, dict):
            raise damaged(f"{key} is {_shown(value)}, not an object")
        bad = next((k for k in value if k not in tables), None)
        if bad is not None:
            raise damaged(f"{key} names {_shown(bad)}, which is no table "
                          f"({', '.join(tables)})")
        if key == "tables":
            bad = next((k for k, n in value.items()
                        if isinstance(n, bool) or not isinstance(n, int) or n < 0), None)
            if bad is not None:
                raise damaged(f"tables counts {_shown(value[bad])} rows of {bad}")


def check_confined(root: Path, version_dir: Path, damaged) -> None:
    """``damaged(problem)`` if the version folder, or anything in it, is a symbolic link
    whose target is outside the database folder ``root`` (it is not followed to look)."""
    home = Path(os.path.realpath(root))
    stack = [Path(version_dir)]
    while stack:
        folder = stack.pop()
        entries = [folder] if folder == version_dir else []
        try:
            with os.scandir(folder) as listing:
                entries += [Path(e.path) for e in listing]
        except OSError as exc:
            raise damaged(f"{folder} cannot be listed: {exc.strerror or exc}") from None
        for path in entries:
            if path.is_symlink():
                target = Path(os.path.realpath(path))
                if not target.is_relative_to(home):
                    raise damaged(f"{path} is a symbolic link leaving the database (to "
                                  f"{target}); refused")
            elif path != folder and path.is_dir():
                stack.append(path)


def check_channels(db) -> None:
    """DataError naming the ``channels`` table unless it is a schema the motion can be
    read with: a row per channel (as many as the manifest's ``n_channels``), unique
    printable names, one kind (the manifest's) and one unit, a point's coordinates as
    three channels ``<point>.x``, ``.y``, ``.z`` in that order, and every channel a
    column of the ``frames`` table (its first file's footer)."""
    table = db.table("channels")
    if "name" not in table.column_names:
        raise db.damaged("channels", "no column name")
    # group, kind and units are checked where present (ingest.clip.stored_schema, which
    # reads them, says when one is missing).
    columns = {c: table.column(c) for c in ("name", "group", "kind", "units")
               if c in table.column_names}
    for column, values in columns.items():
        if not pa.types.is_string(values.type) or values.null_count:
            raise db.damaged("channels", f"its {column}s are not all text ({values.type})")
    names = columns["name"].to_pylist()
    if not names:
        raise db.damaged("channels", "no channels")
    expected = db.manifest.get("n_channels")
    if isinstance(expected, int) and expected != len(names):
        raise db.damaged("channels", f"{len(names)} channels, the manifest {expected}")
    bad = next((n for n in names if not n or not n.isprintable()), None)
    if bad is not None:
        raise db.damaged("channels", f"channel name {_shown(bad)}")
    if len(set(names)) != len(names):
        twice = next(n for n in names if names.count(n) > 1)
        raise db.damaged("channels", f"channel {_shown(twice)} is named twice")
    # One kind of motion a database; its units may differ by channel (an iPhone take's
    # shapes are unitless and its head angles radians; animation curves mix mm and rad).
    if "kind" in columns:
        values = pc.unique(columns["kind"]).to_pylist()
        if len(values) != 1:
            raise db.damaged("channels", f"{len(values)} kinds ({_shown(values[:3])}), "
                             "not one")
    kind = columns["kind"][0].as_py() if "kind" in columns else None
    if None not in (db.manifest.get("kind"), kind) and db.manifest["kind"] != kind:
        raise db.damaged("channels", f"its kind is {_shown(kind)}, the manifest's "
                         f"{_shown(db.manifest.get('kind'))}")
    problem = point_triples_problem(names)
    if problem:
        raise db.damaged("channels", problem)
    frames = db.table_path("frames")
    files = sorted(frames.glob("*=*/*.parquet")) if frames.is_dir() else []
    if files:
        try:
            have = set(pq.read_schema(files[0]).names)
        except (OSError, pa.ArrowException):
            return  # the read of frames says what is wrong with the file
        absent = [n for n in names if n not in have]
        if absent:
            raise db.damaged("frames", f"no column for channel {_shown(absent[0])}"
                             f"{f' (and {len(absent) - 1} more)' if len(absent) > 1 else ''}"
                             ": it does not match the channels table")


def point_triples_problem(names) -> str:
    """What is wrong with the points' coordinates among channel ``names`` (empty if
    nothing): each channel ending in ``.x``, ``.y`` or ``.z`` must be one of three
    consecutive channels ``<point>.x``, ``<point>.y``, ``<point>.z``, as motion files
    (C3D) and the kernels read them."""
    names = list(names)
    i = 0
    while i < len(names):
        name = names[i]
        if name.endswith((".x", ".y", ".z")):
            label = name[:-2]
            if names[i:i + 3] != [f"{label}.x", f"{label}.y", f"{label}.z"]:
                found = ", ".join(names[i:i + 3])
                return (f"channel {i} ({name}) is a point's coordinate without its "
                        f"{label}.x, .y, .z in order (found {found})")
            i += 3
        else:
            i += 1
    return ""


def _rule_columns(name: str, schema_names, is_float) -> dict[str, tuple[float, bool]]:
    rules = RULES.get(name, {})
    out = {c: r for c, r in rules.items() if c != "*" and c in schema_names}
    if "*" in rules:
        out.update({c: rules["*"] for c in schema_names if c not in out and is_float(c)})
    return out


def _broken(value: float, bound: tuple[float, bool]) -> bool:
    low, strict = bound
    return not math.isfinite(value) or value < low or (strict and value == low)


def _rule_text(column: str, value, bound: tuple[float, bool]) -> str:
    need = {POSITIVE: "> 0", NON_NEGATIVE: ">= 0"}.get(bound, "finite")
    value = value + 0 if isinstance(value, float) else value  # Parquet's min 0 is -0.0
    return f"{column} {value!r} (must be {need}" + (", finite)" if bound != FINITE else ")")


def check_statistics(db) -> None:
    """DataError naming the table and file if a footer's statistics (a row group's min
    and max) show a value of a column of :data:`RULES` out of its bound, in any table of
    ``db``: footers only, no value read (NaN is in no statistics: :func:`check_values`
    sees it when the values are read)."""
    for name in RULES:
        path = db.table_path(name)
        for f in db.files(name):
            try:
                meta = pq.read_metadata(f)
            except (OSError, pa.ArrowException) as exc:
                raise db.damaged(name, f"cannot be read: {_first_line(exc)}") from None
            _check_footer(db, name, f.name if f == path else f.relative_to(path), meta)


def _check_footer(db, name: str, where, meta: pq.FileMetaData) -> None:
    schema = meta.schema
    leaves = {schema.column(c).path: c for c in range(meta.num_columns)}
    floats = {p for p, c in leaves.items() if schema.column(c).physical_type in ("FLOAT",
                                                                               "DOUBLE")}
    rules = _rule_columns(name, leaves, floats.__contains__)
    for g in range(meta.num_row_groups):
        group = meta.row_group(g)
        for column, bound in rules.items():
            stats = group.column(leaves[column]).statistics
            if stats is None or not stats.has_min_max:
                continue
            for value in (stats.min, stats.max):
                if isinstance(value, int | float) and _broken(float(value), bound):
                    raise db.damaged(name, f"{where}: {_rule_text(column, value, bound)}")


def check_text(db, name: str, path: Path, where, meta: pq.FileMetaData) -> None:
    """DataError if a text value of the file at ``path`` is longer than
    :data:`MAX_TEXT_BYTES`. Only the text columns one of whose chunks is that large
    uncompressed (the footer says so; a chunk holds its values) are decoded, a few rows
    at a time."""
    schema = meta.schema
    suspects: dict[str, int] = {}  # column -> its largest chunk, uncompressed
    for c in range(meta.num_columns):
        column = schema.column(c)
        if column.physical_type != "BYTE_ARRAY" or column.logical_type.type != "STRING":
            continue
        largest = max((meta.row_group(g).column(c).total_uncompressed_size
                       for g in range(meta.num_row_groups)), default=0)
        if largest > MAX_TEXT_BYTES:
            suspects[column.path] = largest
    if not suspects:
        return
    flat = sorted(c for c in suspects if "." not in c)  # nested: no text in lists here
    try:
        # Read as dictionaries: a dictionary string repeated in every row is then held
        # once, not decoded into each, so a row group's chunk is read at once (2 rows at
        # a time, a 7 MB chunk of clips' ``extra`` took 15 s at 211k clips).
        reader = pq.ParquetFile(path, pre_buffer=False, buffer_size=1 << 20,
                                read_dictionary=flat, **READ_OPTIONS)
        for column in flat:
            for g in range(meta.num_row_groups):
                read = reader.read_row_group(g, columns=[column]).column(0)
                longest = max((pc.max(pc.binary_length(
                    chunk.dictionary if pa.types.is_dictionary(chunk.type) else chunk)
                ).as_py() or 0 for chunk in read.chunks), default=0)
                if longest > MAX_TEXT_BYTES:
                    raise db.damaged(name, f"{where}: a {column} value of {longest} bytes, "
                                     f"more than {MAX_TEXT_BYTES} (not read)")
    except (OSError, pa.ArrowException) as exc:
        raise db.damaged(name, f"cannot be read: {_first_line(exc)}") from None


def check_values(db, name: str, table: pa.Table) -> None:
    """DataError naming table ``name`` if a value read of a column of :data:`RULES` is
    out of its bound: NaN, infinite, negative ..."""
    rules = _rule_columns(name, table.column_names,
                          lambda c: pa.types.is_floating(table.schema.field(c).type))
    for column, bound in rules.items():
        values = table.column(column)
        if not (pa.types.is_integer(values.type) or pa.types.is_floating(values.type)):
            raise db.damaged(name, f"{column} is {values.type}, not numbers")
        if len(values) == values.null_count:
            continue
        low, strict = bound
        data = numbers(values, null=max(low, 0.0) + 1.0)  # a null breaks no bound
        if data.dtype.kind == "f":
            bad = ~np.isfinite(data)
            bad |= (data <= low) if strict else (data < low)
        else:
            bad = (data <= low) if strict else (data < low)
        if bad.any():
            row = int(np.argmax(bad))
            raise db.damaged(name, _whose(table, row) + _rule_text(column, data[row].item(),
                                                                   bound))


def _whose(table: pa.Table, row: int) -> str:
    """"clip <corpus>/<clip_id>: " for a row of a table of clips' rows, else ""."""
    if "clip_id" not in table.column_names:
        return ""
    clip = table.column("clip_id")[row].as_py()
    corpus = table.column("corpus")[row].as_py() if "corpus" in table.column_names else None
    return f"clip {corpus + '/' if corpus else ''}{clip}: "


def _shown(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _first_line(exc: Exception) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__


__all__ = ["MAX_TEXT_BYTES", "READ_OPTIONS", "RULES", "WRITE_OPTIONS",
           "check_channels", "check_confined", "check_manifest", "check_statistics",
           "check_text", "check_values", "plain_name", "point_triples_problem"]
