"""The studio's live tab: the face driven by ``animegraph live --websocket PORT``.

The page opens a WebSocket to the studio (``/api/live?port=N``); the studio connects to
the live command's server at ``ws://127.0.0.1:N/`` (that host only: the page names a
port, never a host) and reads its documented JSON frames (:mod:`animegraph.live.websocket`:
``hello`` with the channels and frame rate, ``frame`` with the values, ``end``). Each
frame is carried onto the face as a clip is (:meth:`FaceBuilder.blocks`) and sent to the
page as one binary animation message of one frame (:func:`animegraph.apps.studio.face.pack`);
the page draws the latest. A frame that arrives while the one before is still being
deformed is dropped (the face shows the newest, as the live command's own clients do).
Lines of status and errors go to the page as JSON text messages.
"""

from __future__ import annotations

import asyncio
import json

import aiohttp
import numpy as np
from aiohttp import web

from animegraph.apps.studio.api import in_thread, studio
from animegraph.apps.studio.face import pack
from db.errors import AnimeGraphError


def _port(request: web.Request) -> int:
    text = request.query.get("port", "")
    if not text.isdigit() or not 1 <= int(text) <= 65535:
        raise web.HTTPBadRequest(text=f"port must be 1 to 65535 (the live command's "
                                      f"--websocket), got {text!r}")
    return int(text)


async def live(request: web.Request) -> web.WebSocketResponse:
    """Relay the live command's frames to the page, carried onto the face."""
    port = _port(request)
    state = studio(request)
    page = web.WebSocketResponse(heartbeat=30)
    await page.prepare(request)
    url = f"ws://127.0.0.1:{port}/"
    try:
        async with aiohttp.ClientSession() as session, session.ws_connect(url) as source:
            await page.send_json({"type": "status", "text": f"connected to {url}"})
            await _relay(state, source, page)
    except (aiohttp.ClientError, OSError) as exc:
        await page.send_json({"type": "error", "text": f"cannot read {url}: {exc} (is "
                              f"'animegraph live --websocket {port}' running?)"})
    await page.close()
    return page


async def _relay(state, source, page: web.WebSocketResponse) -> None:
    fps, latest = None, None
    busy = False
    frames = dropped = 0

    async def draw(values: np.ndarray, index: int) -> None:
        nonlocal busy
        try:
            blocks = await in_thread(state.face.blocks, values[None], fps)
            await page.send_bytes(pack(blocks, state.face.mesh.n_vertices,
                                       {"kind": "live", "index": index, "phones": []}))
        except (AnimeGraphError, ValueError, ConnectionError) as exc:  # frame, or page gone
            if not page.closed:
                await page.send_json({"type": "error",
                                      "text": f"live frame {index} not drawn: {exc}"})
        finally:
            busy = False

    async for message in source:
        if page.closed:
            break
        if message.type != aiohttp.WSMsgType.TEXT:
            continue
        try:
            data = json.loads(message.data)
        except ValueError:
            continue
        kind = data.get("type") if isinstance(data, dict) else None
        if kind == "hello":
            channels = [str(c) for c in data.get("channels", [])]
            if tuple(channels) != state.face.names:
                await page.send_json({"type": "error", "text": (
                    f"the live stream's {len(channels)} channels are not this database's "
                    f"{len(state.face.names)}: run 'animegraph live' on the studio's database")})
                return
            fps = float(data.get("fps") or 30.0)
            await page.send_json({"type": "status", "text": f"live: {len(channels)} channels "
                                  f"at {fps:g} fps"})
        elif kind == "frame" and fps is not None:
            values = np.asarray(data.get("values", []), dtype=np.float64)
            if values.shape != (len(state.face.names),):
                continue
            frames += 1
            if busy:
                dropped += 1
                continue
            busy = True
            latest = asyncio.ensure_future(draw(values, int(data.get("index", frames))))
        elif kind == "end":
            break
    if latest is not None:
        await latest
    if not page.closed:
        await page.send_json({"type": "end", "text": f"the live stream ended: {frames} frames, "
                              f"{dropped} dropped while the face was drawn"})
