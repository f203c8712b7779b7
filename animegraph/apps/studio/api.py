"""The studio's JSON API over one database: overview, clips, a clip's face and speech,
and SQL.

Every answer reuses the command line's own code: :func:`animegraph.apps.info.database_info`
(``info``), :func:`animegraph.apps.query.run_query` (``query``),
:func:`animegraph.apps.query.load_clip` (``query --export``), :func:`db.sql.run` (``sql``,
its sandbox) and :mod:`animegraph.apps.studio.face` (``render``'s deformation). Nothing the
browser sends names a file: a clip is named by its corpus and id, looked up in the
database's tables. Work that reads Parquet or runs DuckDB goes to a worker thread, so
the server keeps answering while it runs.
"""

from __future__ import annotations

import asyncio
import io
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa
from aiohttp import web

from animegraph.apps.studio.face import FaceBuilder, arkit_shapes_bytes, mesh_json, pack
from db.errors import ParameterError
from db.store import Database

#: Rows of a SQL statement shown in the page; the CSV export takes up to db.sql.ROW_LIMIT.
SQL_PAGE_ROWS = 5000
#: Seconds a statement of the console may run.
SQL_TIMEOUT_S = 30.0
#: Most clips the table lists at once.
MAX_CLIP_ROWS = 5000
#: Clip animations kept in memory, the most recently asked for (a few MB each at most).
FACE_CACHE_CLIPS = 64


@dataclass
class Studio:
    """What every handler shares: the database, its face builder, the outputs made."""

    db: Database
    face: FaceBuilder
    outputs: dict = field(default_factory=dict)
    synth_dir: object = None  # the TemporaryDirectory of uploads and outputs
    model: object = None  # the synthesis Model, loaded on first use
    lock: asyncio.Lock = field(default_factory=asyncio.Lock)
    #: Packed clip animations by (database version, corpus, clip id), oldest first. The
    #: database is a read-only view of one version, so a key never goes stale.
    faces: OrderedDict = field(default_factory=OrderedDict)
    faces_lock: threading.Lock = field(default_factory=threading.Lock)  # worker threads
    #: JSON answers that depend only on the database version (the overview, clip lists
    #: by their query), as futures: a request that comes while one is computed waits on it.
    answers: OrderedDict = field(default_factory=OrderedDict)


#: Clip lists kept by query (the overview is kept too).
ANSWERS_KEPT = 32
#: The clip list the page asks for first (app.js: the table's rows, no filter).
FIRST_CLIPS = {"limit": "500"}


async def remembered(state: Studio, key: tuple, func, *args) -> bytes:
    """``func(*args)`` as JSON bytes, computed in a worker thread once per ``key``; a
    failure is not kept (the next request tries again)."""
    future = state.answers.get(key)
    if future is None:
        future = asyncio.ensure_future(in_thread(lambda: json_bytes(func(*args))))
        state.answers[key] = future
        while len(state.answers) > ANSWERS_KEPT:
            state.answers.popitem(last=False)
        future.add_done_callback(lambda f: f.cancelled() or f.exception() is None
                                 or state.answers.pop(key, None))
    return await asyncio.shield(future)


def json_bytes(value) -> bytes:
    import json

    return json.dumps(value, allow_nan=False).encode()


async def warm(state: Studio) -> None:
    """What the first page asks for, made when the server starts (the overview, the
    first clip list, the mesh's deformer), so that the page finds it ready."""
    try:
        await asyncio.gather(remembered(state, ("overview",), _overview, state.db),
                             remembered(state, _clips_key(FIRST_CLIPS), _clips, state.db,
                                        FIRST_CLIPS),
                             in_thread(lambda: state.face.mesh),
                             in_thread(_ready_to_load, state.db))
    except Exception:  # noqa: BLE001 (a request shows the error; warming is best effort)
        pass


def _ready_to_load(db: Database) -> None:
    """What a clip's first load would pay once: the tables' footers checked, the model
    arrays read, the modules it uses imported, the ARKit fit's matrix made (3 s of the
    first click under load)."""
    import animegraph.apps.query  # noqa: F401
    import animegraph.synthesis  # noqa: F401 (load_clip's to_world: 1 s of imports)
    from animegraph.apps.studio.face import arkit_fit_matrix

    for name in ("channels", "clips", "frames", "audio"):
        db.check_rows(name)
    db.arrays()
    arkit_fit_matrix()


def _clips_key(query) -> tuple:
    return ("clips", *sorted((k, v) for k, v in query.items() if k != "token"))


STUDIO = web.AppKey("studio", Studio)


def studio(request: web.Request) -> Studio:
    return request.app[STUDIO]


async def in_thread(func, *args):
    """``func(*args)`` in the default executor (Parquet, DuckDB, numpy release the GIL)."""
    return await asyncio.get_running_loop().run_in_executor(None, func, *args)


def json_safe(value):
    """A cell as JSON holds it: NaN and infinities as None, bytes as their size, lists
    and nested values recursively."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, bytes | bytearray | memoryview):
        return f"<{len(value)} bytes>"
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if value is None or isinstance(value, bool | int | str):
        return value
    return str(value)  # dates, decimals, times


def table_json(table: pa.Table) -> dict:
    """Columns and rows (lists, by position: a join may repeat a column's name)."""
    columns = [table.column(i).to_pylist() for i in range(table.num_columns)]
    return {"columns": table.column_names,
            "types": [str(t) for t in table.schema.types],
            "rows": [json_safe(list(row)) for row in zip(*columns, strict=True)]}


def _overview(db: Database) -> dict:
    from animegraph.apps.info import database_info

    info = database_info(db)
    clips = db.table("clips", columns=["duration"]).column("duration").to_pylist()
    return json_safe({**info, "clip_durations": clips})


async def overview(request: web.Request) -> web.Response:
    state = studio(request)
    return web.Response(body=await remembered(state, ("overview",), _overview, state.db),
                        content_type="application/json")


def _clips(db: Database, query) -> dict:
    from animegraph.apps.query import QuerySpec, run_query

    def text(name):
        value = query.get(name, "").strip()
        return value or None

    try:
        min_dur = float(query["min_dur"]) if text("min_dur") else None
        limit = int(query["limit"]) if text("limit") else 500
    except ValueError:
        raise ParameterError("min_dur must be a number of seconds and limit a whole "
                             "number") from None
    if not 1 <= limit <= MAX_CLIP_ROWS:
        raise ParameterError(f"limit must be between 1 and {MAX_CLIP_ROWS}, got {limit}")
    spec = QuerySpec(phoneme=text("phoneme"), emotion=text("emotion"), text=text("text"),
                     speaker=text("speaker"), min_dur=min_dur, limit=limit, clips=True,
                     order_by=text("order_by"), descending=query.get("desc") == "1")
    return table_json(run_query(db, spec))


async def clips(request: web.Request) -> web.Response:
    state, query = studio(request), dict(request.query)
    return web.Response(body=await remembered(state, _clips_key(query), _clips, state.db,
                                              query), content_type="application/json")


def _clip_key(request: web.Request) -> tuple[str, str]:
    corpus, clip_id = request.query.get("corpus"), request.query.get("clip_id")
    if not corpus or not clip_id:
        raise ParameterError("name the clip: corpus and clip_id")
    return corpus, clip_id


async def mesh(request: web.Request) -> web.Response:
    face = studio(request).face
    return web.json_response(await in_thread(lambda: mesh_json(face.mesh, face.arkit)))


async def arkit_shapes(request: web.Request) -> web.Response:
    """The canonical mesh's 52 ARKit shapes, float32 (52, 468, 3): an iPhone database's
    morph targets, applied by the page."""
    return web.Response(body=await in_thread(arkit_shapes_bytes),
                        content_type="application/octet-stream",
                        headers={"Cache-Control": "max-age=3600"})


def clip_face_bytes(state: Studio, corpus: str, clip_id: str) -> bytes:
    """A clip's page animation (:func:`animegraph.apps.studio.face.pack`), from the cache
    when it was asked for before."""
    from animegraph.apps.query import load_clip

    key = (state.db.version_dir.name, corpus, clip_id)
    with state.faces_lock:
        if (body := state.faces.get(key)) is not None:
            state.faces.move_to_end(key)
            return body
    clip = load_clip(state.db, corpus, clip_id, speech=False)
    blocks = state.face.blocks(clip.motion, clip.fps)
    phones = [{"phone": p["phone"], "start": p["start"], "end": p["end"]} for p in clip.phones]
    body = pack(blocks, state.face.mesh.n_vertices,
                {"kind": "clip", "corpus": corpus, "clip_id": clip_id,
                 "duration": len(clip.motion) / clip.fps, "phones": phones})
    with state.faces_lock:
        state.faces[key] = body
        while len(state.faces) > FACE_CACHE_CLIPS:
            state.faces.popitem(last=False)
    return body


async def clip_face(request: web.Request) -> web.Response:
    body = await in_thread(clip_face_bytes, studio(request), *_clip_key(request))
    return web.Response(body=body, content_type="application/octet-stream")


def wav_bytes(audio: np.ndarray, sample_rate: int) -> bytes:
    """16-bit PCM WAV of ``audio`` (int16, or float in [-1, 1])."""
    import soundfile as sf

    buffer = io.BytesIO()
    sf.write(buffer, audio, sample_rate, format="WAV", subtype="PCM_16")
    return buffer.getvalue()


def _clip_audio(db: Database, corpus: str, clip_id: str) -> bytes:
    import pyarrow.compute as pc

    from db.errors import DataError

    mask = (pc.field("corpus") == corpus) & (pc.field("clip_id") == clip_id)
    rows = db.table("audio", filter=mask).to_pylist()
    if not rows or not rows[0]["pcm16"] or len(rows[0]["pcm16"]) % 2:
        raise DataError(f"clip {clip_id!r} of corpus {corpus!r} has no speech in the database")
    return wav_bytes(np.frombuffer(rows[0]["pcm16"], dtype="<i2"), int(rows[0]["sample_rate"]))


async def clip_audio(request: web.Request) -> web.Response:
    body = await in_thread(_clip_audio, studio(request).db, *_clip_key(request))
    return web.Response(body=body, content_type="audio/wav")


async def _sql_text(request: web.Request) -> str:
    if request.content_type == "application/json":
        payload = await request.json()
        sql = payload.get("sql") if isinstance(payload, dict) else None
    else:
        sql = (await request.post()).get("sql")
    if not isinstance(sql, str):
        raise ParameterError("send the SQL as 'sql'")
    return sql


def _sql(db: Database, sql: str, row_limit: int) -> list:
    from db.sql import run

    return run(db, sql, row_limit=row_limit, timeout=SQL_TIMEOUT_S)


async def sql(request: web.Request) -> web.Response:
    """Each statement's columns and rows (at most :data:`SQL_PAGE_ROWS`), or the
    sandbox's one-line refusal (a 400 answer, as every user error)."""
    results = await in_thread(_sql, studio(request).db, await _sql_text(request),
                              SQL_PAGE_ROWS)
    return web.json_response({"statements": [{"sql": r.sql, "truncated": r.truncated,
                                              **table_json(r.table)} for r in results]})


async def sql_csv(request: web.Request) -> web.Response:
    """The last statement's rows as CSV (``animegraph sql --format csv``'s text)."""
    from animegraph.apps.tabular import format_table
    from db.sql import ROW_LIMIT

    results = await in_thread(_sql, studio(request).db, await _sql_text(request), ROW_LIMIT)
    text = format_table(results[-1].table, "csv")
    return web.Response(text=text, content_type="text/csv", headers={
        "Content-Disposition": 'attachment; filename="query.csv"'})
