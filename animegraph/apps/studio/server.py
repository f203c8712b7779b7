"""The studio's web server (aiohttp): routes, the token guard, one error format, the
static page, and :func:`serve` (what ``animegraph studio`` runs).

Safe by default:

* bound to 127.0.0.1 only;
* a random token (:func:`secrets.token_urlsafe`) is required on every request, in the
  URL once (``?token=``) and then in a cookie the answer sets, as Jupyter does; a
  request without it gets 403;
* no path from the browser reaches the file system: the page's files are a fixed list
  made when the server starts (:func:`static_files`), clips are named by their ids in
  the database, outputs by random ids and their own list of files;
* the live tab names a port, never a host: the studio reads WebSocket frames from
  127.0.0.1 only (:mod:`animegraph.apps.studio.live`);
* SQL runs only in :mod:`db.sql`'s sandbox; uploads are bounded in size and go to the
  studio's own temporary folder, deleted when it stops;
* every error is one line: JSON ``{"error": ...}`` for the API, a small page otherwise;
* the page may load nothing from elsewhere and may not be framed (its content policy,
  :func:`content_policy`), and no answer sends a Referer on.
"""

from __future__ import annotations

import asyncio
import base64
import hashlib
import html
import logging
import re
import secrets
import tempfile
import webbrowser
from collections.abc import Callable
from importlib import resources
from pathlib import Path

from aiohttp import web

from animegraph.apps.studio import api, live, synth
from animegraph.apps.studio.face import FaceBuilder
from db.errors import AnimeGraphError
from db.store import Database

logger = logging.getLogger(__name__)

#: The cookie that carries the token after the first request.
COOKIE = "animegraph_studio_token"
TOKEN_KEY = web.AppKey("token", str)
STATIC_KEY = web.AppKey("static", dict)
POLICY_KEY = web.AppKey("policy", str)
WARM_KEY = web.AppKey("warm", asyncio.Future)
#: Content types of the page's files, by suffix (ES modules must be served as JavaScript).
CONTENT_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css",
                 ".txt": "text/plain", ".md": "text/plain", ".svg": "image/svg+xml"}


def static_files() -> dict[str, Path]:
    """The page's files by their URL name (``app.js``, ``vendor/three.module.js``): the
    only files the server sends that it did not make itself."""
    root = Path(str(resources.files("animegraph.apps.studio") / "static"))
    return {path.relative_to(root).as_posix(): path for path in sorted(root.rglob("*"))
            if path.is_file() and path.suffix in CONTENT_TYPES}


def content_policy(index_html: str) -> str:
    """The page's Content-Security-Policy: its own files only (no other site's script,
    style, media or connection), its one inline script (the import map) by its hash, and
    no framing by another page."""
    found = re.search(r'<script type="importmap">(.*?)</script>', index_html, re.S)
    digest = base64.b64encode(hashlib.sha256(found.group(1).encode()).digest()).decode() \
        if found else ""
    scripts = f"'self' 'sha256-{digest}'" if digest else "'self'"
    return (f"default-src 'self'; script-src {scripts}; style-src 'self' 'unsafe-inline'; "
            "img-src 'self' data:; media-src 'self' blob:; connect-src 'self'; "
            "object-src 'none'; base-uri 'none'; frame-ancestors 'none'")


@web.middleware
async def headers(request: web.Request, handler: Callable) -> web.StreamResponse:
    """Every answer: no type sniffing, no framing, no Referer (the first URL holds the
    token), the page's content policy."""
    response = await handler(request)
    response.headers.setdefault("X-Content-Type-Options", "nosniff")
    response.headers.setdefault("X-Frame-Options", "DENY")
    response.headers.setdefault("Referrer-Policy", "no-referrer")
    response.headers.setdefault("Content-Security-Policy", request.app[POLICY_KEY])
    return response


def _wants_json(request: web.Request) -> bool:
    return request.path.startswith("/api/")


def error_response(request: web.Request, status: int, message: str) -> web.Response:
    """The one error format: JSON for the API, a page for the rest."""
    if _wants_json(request):
        return web.json_response({"error": message}, status=status)
    page = (f"<!doctype html><meta charset=utf-8><title>animegraph studio: error</title>"
            f"<body style='font-family:sans-serif;background:#202124;color:#eee;padding:2em'>"
            f"<h1>{status}</h1><p id=error>{html.escape(message)}</p></body>")
    return web.Response(text=page, status=status, content_type="text/html")


@web.middleware
async def errors(request: web.Request, handler: Callable) -> web.StreamResponse:
    """Every failure as one line: user errors (the project's own) are 400, a missing
    route 404, anything else 500 with the traceback kept in the server's log."""
    try:
        return await handler(request)
    except web.HTTPException as exc:
        if exc.status < 400:
            raise
        reason = exc.text if exc.text and not exc.text.startswith(f"{exc.status}:") \
            else exc.reason
        return error_response(request, exc.status, reason)
    except AnimeGraphError as exc:
        return error_response(request, 400, str(exc))
    except asyncio.CancelledError:
        raise
    except Exception as exc:
        logger.exception("studio: %s %s failed", request.method, request.path)
        return error_response(request, 500, f"internal error: {type(exc).__name__}: {exc}")


@web.middleware
async def token_guard(request: web.Request, handler: Callable) -> web.StreamResponse:
    """403 unless the request carries the token (``?token=`` or the cookie); a good
    ``?token=`` sets the cookie."""
    token = request.app[TOKEN_KEY].encode()
    given = request.query.get("token")
    by_query = given is not None and secrets.compare_digest(given.encode(), token)
    cookie = request.cookies.get(COOKIE)
    if not by_query and not (cookie is not None and secrets.compare_digest(cookie.encode(),
                                                                           token)):
        return error_response(request, 403, "forbidden: open the studio with the URL "
                              "'animegraph studio' printed (it carries the token)")
    response = await handler(request)
    if by_query:
        response.set_cookie(COOKIE, request.app[TOKEN_KEY], httponly=True, samesite="Strict",
                            path="/")
    return response


async def index(request: web.Request) -> web.Response:
    return _static(request, "index.html")


async def static(request: web.Request) -> web.Response:
    return _static(request, request.match_info["name"])


def _static(request: web.Request, name: str) -> web.Response:
    path = request.app[STATIC_KEY].get(name)
    if path is None:
        raise web.HTTPNotFound(text=f"no page file {name!r}")
    return web.Response(body=path.read_bytes(), content_type=CONTENT_TYPES[path.suffix],
                        headers={"Cache-Control": "no-cache"})


def make_app(db_path: Path, token: str) -> web.Application:
    """The studio's application on the database at ``db_path``.

    Raises
    ------
    DataError
        If ``db_path`` is not a readable database.
    """
    db = Database.open(db_path)
    names = tuple(ch["name"] for ch in db.table("channels", columns=["name"]).to_pylist())
    app = web.Application(middlewares=[headers, errors, token_guard],
                          client_max_size=synth.MAX_UPLOAD_BYTES + (1 << 20))
    app[TOKEN_KEY] = token
    app[STATIC_KEY] = static_files()
    app[POLICY_KEY] = content_policy(app[STATIC_KEY]["index.html"].read_text())
    state = api.Studio(db=db, face=FaceBuilder(names),
                       synth_dir=tempfile.TemporaryDirectory(prefix="animegraph-studio-"))
    app[api.STUDIO] = state

    async def cleanup(app: web.Application) -> None:
        state.synth_dir.cleanup()

    async def start_warming(app: web.Application) -> None:
        app[WARM_KEY] = asyncio.ensure_future(api.warm(state))

    app.on_startup.append(start_warming)
    app.on_cleanup.append(cleanup)
    app.router.add_get("/", index)
    app.router.add_get("/static/{name:.+}", static)
    app.router.add_get("/api/overview", api.overview)
    app.router.add_get("/api/clips", api.clips)
    app.router.add_get("/api/mesh", api.mesh)
    app.router.add_get("/api/mesh/arkit", api.arkit_shapes)
    app.router.add_get("/api/clip/face", api.clip_face)
    app.router.add_get("/api/clip/audio", api.clip_audio)
    app.router.add_post("/api/sql", api.sql)
    app.router.add_post("/api/sql.csv", api.sql_csv)
    app.router.add_post("/api/synth", synth.synth)
    app.router.add_get("/api/live", live.live)
    app.router.add_get("/api/outputs/{out_id}/face", synth.output_face)
    app.router.add_get("/api/outputs/{out_id}/files/{name}", synth.output_file)
    return app


async def _serve(app: web.Application, port: int, on_ready: Callable[[str], None]) -> None:
    runner = web.AppRunner(app, access_log=None)
    await runner.setup()
    try:
        site = web.TCPSite(runner, "127.0.0.1", port)
        await site.start()
        host, bound = runner.addresses[0][:2]
        on_ready(f"http://{host}:{bound}/?token={app[TOKEN_KEY]}")
        await asyncio.Event().wait()  # until Ctrl-C (or SIGTERM) ends the process
    finally:
        await runner.cleanup()


def serve(db_path: Path, *, port: int = 8765, open_browser: bool = True,
          say: Callable[[str], None] = print) -> None:
    """Run the studio until interrupted: print its URL (with the token), open the
    browser (:mod:`webbrowser`, which honours ``$BROWSER``) unless told not to.

    Raises
    ------
    DataError
        If the database cannot be opened.
    OSError
        If the port is taken.
    """
    token = secrets.token_urlsafe(24)
    app = make_app(db_path, token)

    def ready(url: str) -> None:
        say(f"animegraph studio on {db_path}: {url}")
        say("(Ctrl-C stops it)")
        if open_browser:
            webbrowser.open(url)

    asyncio.run(_serve(app, port, ready))
