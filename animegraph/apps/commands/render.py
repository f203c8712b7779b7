"""``animegraph render`` (motion onto a face mesh: video, glTF, OBJ frames) and
``animegraph plot`` (motion over the speech and its phones)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from animegraph.apps.commands.common import UsageError, progress, sidecar_labels


def cmd_render(args: argparse.Namespace) -> int:
    import time

    from animegraph.face.render import deformer_for, render_motion
    from animegraph.motion.files import read_motion
    from ingest.formats.livelink import is_arkit

    size = None if args.size is None else _size(args.size)
    if size is not None and args.output.suffix.lower() not in (".mp4", ".gif", ".png"):
        raise UsageError("animegraph render: --size needs an .mp4, .gif or .png output (a "
                         "glTF or OBJ frames are a mesh, not pictures)")
    if args.fps is not None and not args.fps > 0:
        raise UsageError(f"animegraph render: --fps must be > 0, got {args.fps}")
    if args.mesh is not None and args.marker_map is None:
        raise UsageError("animegraph render: --mesh needs --marker-map (which marker sits on "
                         "which vertex)")
    if args.audio is not None and not args.audio.is_file():
        raise UsageError(f"animegraph render: --audio {args.audio} does not exist")
    if args.beside is not None and not args.beside.is_file():
        raise UsageError(f"animegraph render: --beside {args.beside} does not exist")
    for option, given in (("--beside", args.beside), ("--audio", args.audio)):
        if given is not None and args.output.suffix.lower() != ".mp4":
            raise UsageError(f"animegraph render: {option} needs an .mp4 output (a GIF, PNG, "
                             "glTF or OBJ frames carry neither sound nor a second picture)")
    # the render replaces -o: an input there (the actor's video, the speech) would be lost
    for option, given in (("the motion", args.motion), ("--mesh", args.mesh),
                          ("--marker-map", args.marker_map), ("--audio", args.audio),
                          ("--beside", args.beside)):
        if given is not None and args.output.exists() and Path(given).exists() \
                and args.output.samefile(given):
            raise UsageError(f"animegraph render: -o {args.output} is also {option}: the "
                             "render would replace it")
    phones = _phone_track(args)
    t0 = time.perf_counter()
    motion = read_motion(args.motion)
    if args.db is not None:
        _check_db_channels(args.db, motion)
    deformer = deformer_for(motion.names, mesh_path=args.mesh, map_path=args.marker_map,
                            rest_frame=_rest(motion, args))
    out = render_motion(motion, args.output, deformer=deformer, audio=args.audio,
                        fps=args.fps, phones=phones, size=size, force=args.force,
                        progress=lambda total: progress(total, args.quiet, "frame",
                                                        "rendering"),
                        beside=args.beside)
    what = "curves" if deformer is None else f"{deformer.mesh.name}, " \
        f"{deformer.markers.n_markers} markers"
    if deformer is None and is_arkit(motion.names):
        what = "ARKit blendshapes on the canonical face mesh"
    print(f"animegraph: rendered {motion.duration:.2f} s of motion ({what}) in "
          f"{time.perf_counter() - t0:.1f} s: {out}", file=sys.stderr)
    return 0


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise UsageError(f"animegraph render: --size must be WxH, e.g. 480x540; got "
                         f"{text!r}") from None
    return width, height


def _phone_track(args: argparse.Namespace) -> list[dict]:
    from animegraph.motion.files import read_phone_track

    if args.explain is not None and args.labels is not None:
        raise UsageError(f"animegraph {args.command}: give --explain or --labels, not both")
    labels = args.labels
    if labels is None and args.explain is None:
        labels = sidecar_labels(args.motion)  # what 'query --export' writes by each snippet
    return read_phone_track(labels=labels, explain=args.explain)


def _rest(motion, args: argparse.Namespace):
    """Rest-frame marker positions for the deformer, or None for the mesh's own."""
    from animegraph.face.mesh import default_marker_map, load_mesh, motion_points, read_marker_map

    index = args.rest_frame
    if index is None and args.mesh is None:
        return None
    index = 0 if index is None else index
    if not 0 <= index < motion.n_frames:
        raise UsageError(f"animegraph render: --rest-frame must be in 0-{motion.n_frames - 1}, "
                         f"got {index}")
    from animegraph.face.mesh import canonical_mesh
    from animegraph.motion.files import point_labels

    mesh = load_mesh(args.mesh) if args.mesh is not None else canonical_mesh()
    markers = (read_marker_map(args.marker_map, mesh) if args.marker_map is not None
               else default_marker_map(point_labels(motion.names)))
    return motion_points(motion.names, motion.values[index:index + 1], markers.labels)[0]


def _check_db_channels(db_path: Path, motion) -> None:
    from db.errors import DataError
    from db.store import Database

    names = set(Database.open(db_path).table("channels").column("name").to_pylist())
    extra = [n for n in motion.names if n not in names]
    if extra:
        raise DataError(f"the motion's channels are not the database's: {len(extra)} of "
                        f"{len(motion.names)} are not in it ({', '.join(extra[:3])} ...)")


def cmd_plot(args: argparse.Namespace) -> int:
    from animegraph.apps.plots import plot_motion
    from animegraph.motion.files import read_motion
    from ingest.formats.media import read_audio

    if args.output.suffix.lower() != ".png":
        raise UsageError(f"animegraph plot: -o must end in .png, got {args.output.name!r}")
    phones = _phone_track(args)
    motion = read_motion(args.motion)
    truth = read_motion(args.truth) if args.truth is not None else None
    audio = read_audio(args.audio) if args.audio is not None else None
    plot_motion(motion, args.output, truth=truth, phones=phones, audio=audio,
                title=args.title or args.motion.name, label=args.motion.name,
                say=lambda line: print(f"animegraph: {line}", file=sys.stderr))
    print(f"animegraph: wrote {args.output}", file=sys.stderr)
    return 0
