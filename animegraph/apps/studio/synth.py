"""Synthesis in the studio: a recording uploaded from the page, a new line of motion.

The upload is bounded (:data:`MAX_UPLOAD_BYTES`, also the server's request cap), goes
under a name the server chooses into the studio's own temporary folder, and is read by
the reader ``synth`` uses (:func:`ingest.formats.media.read_audio`). The line is
synthesized by :func:`animegraph.synthesis.synthesize` (README, "From Python"); its
motion is written in the database's formats beside it. An output is named by a random
id, and only the files the studio wrote for it can be downloaded: the browser names an
id and a file of that output's list, never a path.
"""

from __future__ import annotations

import secrets
from dataclasses import dataclass
from pathlib import Path

from aiohttp import web

from animegraph.apps.studio.api import Studio, in_thread, pack, studio, wav_bytes
from db.errors import DataError, ParameterError
from ingest.formats.media import MEDIA_SUFFIXES

#: Largest recording the page may upload (the server refuses a larger request).
MAX_UPLOAD_BYTES = 64 << 20
#: Suffixes of an upload (what ``synth`` reads: libsndfile's, and the containers ffmpeg
#: opens, among them the WebM of the page's microphone recording); anything else is refused.
AUDIO_SUFFIXES = (".wav", ".flac", ".ogg", ".mp3") + MEDIA_SUFFIXES
#: The synthesis paths the page offers: the README's default for a line with a
#: transcript (k-best 20, as ``batch``), and the paper's (one anime a phoneme, exact search).
METHODS = {"k-best": 20, "paper": None}
#: Most outputs kept; the oldest is forgotten (and its files deleted) beyond it.
MAX_OUTPUTS = 50


@dataclass(frozen=True)
class Output:
    """A line the studio made: its files (name to path, inside the studio's folder) and
    the page animation."""

    files: dict
    face: bytes


async def _upload(request: web.Request, folder: Path) -> tuple[Path | None, dict]:
    """The multipart form: the recording saved as ``folder/upload<suffix>``, the fields."""
    if request.content_type != "multipart/form-data":
        raise ParameterError("send the recording and its fields as multipart/form-data")
    reader = await request.multipart()
    fields, audio = {}, None
    while (part := await reader.next()) is not None:
        if part.name == "audio" and part.filename:
            suffix = Path(part.filename).suffix.lower()
            if suffix not in AUDIO_SUFFIXES:
                raise ParameterError(f"the recording must be one of {', '.join(AUDIO_SUFFIXES)}; "
                                     f"got {suffix or 'no extension'}")
            audio = folder / f"upload{suffix}"
            size = 0
            with audio.open("wb") as handle:
                while chunk := await part.read_chunk(1 << 16):
                    size += len(chunk)
                    if size > MAX_UPLOAD_BYTES:
                        limit = (f"{MAX_UPLOAD_BYTES >> 20} MB" if MAX_UPLOAD_BYTES >= 1 << 20
                                 else f"{MAX_UPLOAD_BYTES} bytes")
                        raise ParameterError(f"the recording is over {limit}: the studio "
                                             "takes no larger one")
                    handle.write(chunk)
        elif part.name in ("text", "emotion", "method"):
            fields[part.name] = (await part.text())[:10_000].strip()
    return audio, fields


def _synthesize(state: Studio, folder: Path, audio_path: Path, fields: dict) -> Output:
    import numpy as np

    from animegraph.emotion.control import check_names, parse_emotion
    from animegraph.motion.files import motion_suffix
    from animegraph.synthesis import Model, check_not_silent, synthesize, write_motion
    from ingest.formats.livelink import is_arkit
    from ingest.formats.media import read_audio

    method = fields.get("method") or "k-best"
    if method not in METHODS:
        raise ParameterError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if state.model is None:
        state.model = Model.load(state.db.root)
    model = state.model
    emotion = parse_emotion(fields.get("emotion") or None)
    emotion = check_names(emotion, model.emotion_model, model.graph.emotions)
    audio, rate = read_audio(audio_path)
    check_not_silent(audio)
    out = synthesize(model, audio, rate, text=fields.get("text") or None, emotion=emotion,
                     k_best=METHODS[method])
    files = {"speech.wav": folder / "speech.wav"}
    files["speech.wav"].write_bytes(wav_bytes(np.clip(audio, -1, 1), rate))
    suffixes = [motion_suffix(model.names, model.kind), ".csv", ".npz"]
    if is_arkit(model.names):
        suffixes.insert(0, ".livelink.csv")
    for suffix in dict.fromkeys(suffixes):
        path = folder / f"motion{suffix}"
        write_motion(out, model, path)
        files[path.name] = path
    phones = [{"phone": p.phone, "start": p.start, "end": p.end} for p in out.phones]
    header = {"kind": "synthesis", "duration": len(audio) / rate, "phones": phones,
              "segmentation": out.segmentation, "warnings": list(out.warnings),
              "emotion": str(out.emotion.target) if out.emotion.target else None,
              "method": method, "nearest": nearest_clip(state, out.explain)}
    return Output(files=files, face=pack(state.face.blocks(out.motion, out.fps),
                                         state.face.mesh.n_vertices, header))


def nearest_clip(state: Studio, explain: list[dict]) -> dict | None:
    """The recorded clip nearest the line by the search: the one whose animes the search
    picked for most of its phones (silences left out; ties to the earliest picked). Its
    corpus is looked up by the clip id (the first, if two corpora share the id)."""
    import pyarrow.compute as pc

    picks = [row["clip_id"] for row in explain if row["phone"] != "SIL"] or \
        [row["clip_id"] for row in explain]
    if not picks:
        return None
    counts = {c: picks.count(c) for c in dict.fromkeys(picks)}
    clip_id = max(counts, key=counts.get)
    rows = state.db.table("clips", columns=["corpus", "emotion"],
                          filter=pc.field("clip_id") == clip_id).to_pylist()
    if not rows:
        return None
    return {"corpus": rows[0]["corpus"], "clip_id": clip_id, "emotion": rows[0]["emotion"],
            "phones_from_it": counts[clip_id], "phones": len(picks)}


async def synth(request: web.Request) -> web.Response:
    """Upload and synthesize; the output's id and the files it made."""
    import shutil

    state = studio(request)
    out_id = secrets.token_hex(8)
    folder = Path(state.synth_dir.name) / out_id
    folder.mkdir()
    try:
        audio, fields = await _upload(request, folder)
        if audio is None:
            raise ParameterError("choose a recording to upload")
        async with state.lock:  # one synthesis at a time: it takes the machine's cores
            output = await in_thread(_synthesize, state, folder, audio, fields)
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    audio.unlink(missing_ok=True)  # what the browser sent is not an output
    state.outputs[out_id] = output
    while len(state.outputs) > MAX_OUTPUTS:
        oldest = next(iter(state.outputs))
        del state.outputs[oldest]
        shutil.rmtree(Path(state.synth_dir.name) / oldest, ignore_errors=True)
    return web.json_response({"id": out_id, "files": sorted(output.files)})


def _output(request: web.Request) -> Output:
    output = studio(request).outputs.get(request.match_info["out_id"])
    if output is None:
        raise DataError("no such output: the studio made none by that id (or forgot it)")
    return output


async def output_face(request: web.Request) -> web.Response:
    return web.Response(body=_output(request).face, content_type="application/octet-stream")


async def output_file(request: web.Request) -> web.FileResponse:
    """A file the studio wrote for this output, by its name in the output's list."""
    output, name = _output(request), request.match_info["name"]
    if name not in output.files:
        raise DataError(f"output {request.match_info['out_id']} has no file {name!r}")
    inline = name == "speech.wav" and request.query.get("inline") == "1"
    disposition = "inline" if inline else f'attachment; filename="{name}"'
    return web.FileResponse(output.files[name], headers={"Content-Disposition": disposition})
