"""``animegraph live``: speech in as it is spoken, facial motion out in real time
(:mod:`animegraph.live`): to Live Link (Unreal, MetaHuman), WebSocket clients and a
recording."""

from __future__ import annotations

import argparse
import sys

from animegraph.apps.commands.common import UsageError


def cmd_live(args: argparse.Namespace) -> int:
    from animegraph.live import Stream
    from animegraph.live.run import run
    from animegraph.live.stream import (
        DEFAULT_BACKLOG_MS,
        DEFAULT_SETTING,
        LOW_LATENCY,
        check_rate,
    )
    from animegraph.synthesis import Model
    from db.errors import DataError, ParameterError

    if not (args.livelink or args.websocket is not None or args.record):
        raise UsageError("animegraph live: say where the frames go: --livelink HOST:PORT, "
                         "--websocket PORT and/or --record DIR")
    if args.websocket is not None and not 0 <= args.websocket < 65536:
        raise UsageError(f"animegraph live: --websocket takes a port 0-65535, got "
                         f"{args.websocket}")
    if args.livelink:  # before any work: a typo here is the command line's
        from animegraph.live.livelink import parse_target

        try:
            parse_target(args.livelink)
        except ParameterError as exc:
            raise UsageError(f"animegraph live: {exc}") from None
    source = _source(args)
    try:
        check_rate(source.sample_rate)
    except ParameterError as exc:
        raise UsageError(f"animegraph live: {exc}") from None
    model = Model.load(args.db)
    guide = _guide(args)
    try:
        setting = dict(LOW_LATENCY if args.low_latency else DEFAULT_SETTING)
        for name, given in (("lookahead_ms", args.lookahead), ("hop_ms", args.hop),
                            ("guide_share", args.guide_share),
                            ("phones_engine", args.phones_engine)):
            if given is not None:
                setting[name] = given
        stream = Stream(model, sample_rate=source.sample_rate, **setting,
                        emotion=args.emotion, guide=guide,
                        backlog_ms=None if args.fast else DEFAULT_BACKLOG_MS, text=args.text,
                        threads=args.threads)
    except (ParameterError, DataError) as exc:
        raise UsageError(f"animegraph live: {exc}") from None
    outputs = []
    try:
        if args.livelink:
            from animegraph.live.livelink import LiveLinkSender
            from ingest.formats.livelink import is_arkit

            convert = None
            if not is_arkit(model.names):  # markers or landmarks: onto the 52 shapes
                from animegraph.live.arkit_map import PointsToArkit

                convert = PointsToArkit(model)
            outputs.append(LiveLinkSender(args.livelink, model.names, stream.fps,
                                          subject=args.subject, convert=convert))
        if args.websocket is not None:
            from animegraph.live.websocket import FrameServer

            server = FrameServer(args.websocket, model.names, stream.fps, host=args.host)
            outputs.append(server)
            print(f"animegraph: live: WebSocket frames on ws://{args.host}:{server.port}/",
                  file=sys.stderr)
        recorder = None
        if args.record:
            from animegraph.live.record import Recorder

            recorder = Recorder(args.record, model.names, model.kind, stream.fps,
                                source.sample_rate)
    except BaseException:
        for output in outputs:
            output.close()
        raise
    print(f"animegraph: live: {model.graph.n_nodes} animes at {stream.fps:g} fps; "
          f"look-ahead {stream.lookahead_s * 1000:g} ms, an update every "
          f"{stream.hop_s * 1000:g} ms; "
          f"{_where(args)} (Ctrl-C ends)", file=sys.stderr)
    try:
        take = run(stream, source, outputs, recorder=recorder)
    finally:
        if recorder is not None and recorder.closed:
            print(f"animegraph: live: recorded {recorder.motion_path} and "
                  f"{recorder.audio_path}", file=sys.stderr)
    for line in _summary(stream, take, outputs, paced=not args.fast):
        print(f"animegraph: live: {line}", file=sys.stderr)
    return 0


def _source(args: argparse.Namespace):
    from animegraph.live.sources import FileSource, MicSource, PcmSource, WebSocketSource
    from animegraph.live.stream import check_rate
    from db.errors import ParameterError

    if args.source.startswith("ws:"):
        port = args.source[3:]
        if not port.isdigit() or int(port) > 65535:
            raise UsageError(f"animegraph live: --source {args.source}: give ws:PORT, a "
                             "port to listen on (0-65535)")
        if args.rate is None:
            raise UsageError("animegraph live: --source ws:PORT (raw 16-bit PCM from a "
                             "WebSocket client) needs --rate HZ")
        try:
            check_rate(args.rate)
        except ParameterError as exc:
            raise UsageError(f"animegraph live: {exc}") from None
        source = WebSocketSource(int(port), args.rate, host=args.host)
        print(f"animegraph: live: waiting for PCM at ws://{args.host}:{source.port}/",
              file=sys.stderr, flush=True)
        return source
    if args.source == "-":
        if args.rate is None:
            raise UsageError("animegraph live: --source - (raw 16-bit PCM on stdin) needs "
                             "--rate HZ")
        return PcmSource(args.rate)
    if args.rate is not None and args.source != "mic":
        raise UsageError("animegraph live: --rate is for --source -, ws:PORT and mic; a "
                         "file has its own")
    if args.source == "mic":
        return MicSource(args.rate or 16000)
    from pathlib import Path

    path = Path(args.source)
    if not path.is_file():
        raise UsageError(f"animegraph live: --source {args.source}: no such file")
    return FileSource(path, fast=args.fast)


def _guide(args: argparse.Namespace):
    """The offline audio-only default's guide (fitted and stored on first use, as synth
    does), or none with ``--guide none``."""
    if args.guide == "none":
        return None
    from animegraph.apps.commands.synth_plan import load_guide
    from animegraph.synthesis.path import AUDIO_ONLY_GUIDE

    return load_guide(args.db, AUDIO_ONLY_GUIDE, asked=False)


def _where(args: argparse.Namespace) -> str:
    parts = [f"from {'the microphone' if args.source == 'mic' else args.source}"]
    if args.livelink:
        parts.append(f"Live Link to {args.livelink}")
    if args.record:
        parts.append(f"recording into {args.record}")
    return ", ".join(parts)


def _summary(stream, take, outputs, *, paced: bool) -> list[str]:
    import numpy as np

    lines = [f"{take.frames} frames for {take.heard_s:.1f} s of speech; {stream.stats.updates} "
             f"updates, {stream.stats.cpu_s:.1f} CPU-s ({stream.stats.pauses} in pauses)"]
    if take.sent_at and paced:  # played as fast as possible, arrival means nothing
        lag = (np.asarray(take.sent_at) - np.asarray(take.arrived_at)) * 1000
        lines.append(f"latency from a sample's arrival to its frame: median "
                     f"{np.median(lag):.0f} ms, 95th percentile {np.percentile(lag, 95):.0f} "
                     f"ms, max {lag.max():.0f} ms")
    for output in outputs:
        name = type(output).__name__
        dropped = getattr(output, "dropped", 0)
        if dropped:
            why = "; ".join(f"{k} {v}" for k, v in getattr(output, "errors", {}).items())
            lines.append(f"warning: {name}: {dropped} frames dropped" + (f" ({why})" if why
                                                                          else ""))
        if getattr(output, "disconnected", 0):
            lines.append(f"warning: {name}: {output.disconnected} clients disconnected")
    for what, count in stream.stats.warnings.items():
        lines.append(f"warning: {what} ({count} updates)")
    return lines
