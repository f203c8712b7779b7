"""Rendering motion for an animator: MP4, GIF, PNG, glTF 2.0 (.glb, :mod:`animegraph.face.gltf`)
or OBJ frames.

Point motion (markers, landmarks) is carried onto a face mesh (:mod:`animegraph.face.mesh`,
Cao et al. §7) and drawn as a flat-shaded face (matplotlib's Agg rasteriser, triangles
in depth order), the frames piped as raw RGB into the ffmpeg binary that
``imageio-ffmpeg`` ships, with the speech muxed in. ARKit blendshape curves (an iPhone
capture, an ARKit database) drive the canonical face through the shapes of
:mod:`animegraph.face.arkit` (and become a glTF with ARKit-named morph targets); other
curve motion (no rig here) is drawn as curves over time with the phones and a moving
cursor.

Every output appears complete or not at all: files are written beside the target under
a temporary name and renamed; OBJ frames go to a hidden folder renamed into place; a face
put beside the actor's video is rendered into a hidden folder first, and only the pair
replaces the target.
"""

from __future__ import annotations

import logging
import os
import secrets
import shutil
import subprocess
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

import numpy as np

from animegraph.face.animation import FaceAnimation, animate, animation_bounds
from animegraph.face.arkit import arkit_animation, arkit_weights
from animegraph.face.mesh import Deformer, MarkerMap, Mesh
from animegraph.motion.files import Motion
from db.atomic import check_folder
from db.errors import DataError, ParameterError
from ingest.formats.livelink import is_arkit

logger = logging.getLogger(__name__)

#: Output kinds by extension ("" is a folder of OBJ frames).
FORMATS = (".mp4", ".gif", ".glb", ".png", "")
_SKIN = np.array([0.86, 0.68, 0.58])
_MOUTH = np.array([0.30, 0.06, 0.07])
_EYE = np.array([0.12, 0.10, 0.10])
_LIGHT = np.array([-0.35, 0.45, 0.82])
_LIGHT = _LIGHT / np.linalg.norm(_LIGHT)


def ffmpeg_exe() -> str:
    """The ffmpeg binary shipped by ``imageio-ffmpeg``."""
    import imageio_ffmpeg

    return imageio_ffmpeg.get_ffmpeg_exe()


class FaceRenderer:
    """Draws a mesh, front view, flat-shaded, into RGB frames of a fixed size.

    Parameters
    ----------
    mesh : Mesh
    bounds : np.ndarray, shape (2, 3)
        Lowest and highest x, y, z the animation reaches (sets the framing).
    size : (width, height)
        Pixels; even numbers (H.264 needs them).
    """

    def __init__(self, mesh: Mesh, bounds: np.ndarray, size: tuple[int, int] = (480, 540)):
        import matplotlib

        matplotlib.use("Agg")
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.collections import PolyCollection
        from matplotlib.figure import Figure

        width, height = (int(s) - int(s) % 2 for s in size)
        if width < 16 or height < 16:
            raise ParameterError(f"frame size must be at least 16x16, got {size}")
        self.size = (width, height)
        self.mesh = mesh
        self.is_mouth = np.zeros(len(mesh.faces), dtype=bool)
        self.is_mouth[mesh.mouth] = True
        self.is_eye = np.zeros(len(mesh.faces), dtype=bool)
        self.is_eye[mesh.eyes] = True
        dpi = 100
        self.fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor="0.13")
        self.canvas = FigureCanvasAgg(self.fig)
        ax = self.fig.add_axes((0, 0, 1, 1))
        ax.set_axis_off()
        ax.set_facecolor("0.13")
        lo, hi = np.asarray(bounds)[0], np.asarray(bounds)[1]
        centre = 0.5 * (lo + hi)
        half = 0.55 * max(hi[0] - lo[0], (hi[1] - lo[1]) * width / height)
        ax.set_xlim(centre[0] - half, centre[0] + half)
        half_y = half * height / width
        ax.set_ylim(centre[1] - half_y, centre[1] + half_y)
        self.coll = PolyCollection(np.zeros((0, 3, 2)), edgecolors="face", linewidths=0.4,
                                   antialiaseds=True)
        ax.add_collection(self.coll)
        self.caption = ax.text(0.5, 0.03, "", transform=ax.transAxes, ha="center",
                               va="bottom", color="0.92", fontsize=13, family="monospace")

    def frame(self, vertices: np.ndarray, caption: str = "") -> np.ndarray:
        """RGB image, shape (height, width, 3), uint8, of the mesh at ``vertices``."""
        tri = vertices[self.mesh.faces]  # (n_faces, 3, 3)
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        norm = np.linalg.norm(normal, axis=1)
        normal = normal / np.maximum(norm, 1e-12)[:, None]
        facing = normal[:, 2] > -0.05
        order = np.flatnonzero(facing)[np.argsort(tri[facing, :, 2].mean(axis=1))]
        lambert = np.clip(normal[order] @ _LIGHT, 0.0, 1.0)
        half = _LIGHT + np.array([0.0, 0.0, 1.0])
        spec = np.clip(normal[order] @ (half / np.linalg.norm(half)), 0, 1) ** 24
        base = np.where(self.is_mouth[order, None], _MOUTH,
                        np.where(self.is_eye[order, None], _EYE, _SKIN))
        colour = np.clip(base * (0.28 + 0.72 * lambert[:, None]) + 0.12 * spec[:, None], 0, 1)
        self.coll.set_verts(tri[order, :, :2])
        self.coll.set_facecolor(colour)
        self.coll.set_edgecolor(colour)
        self.caption.set_text(caption)
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        import matplotlib.pyplot as plt

        plt.close(self.fig)


def captions(phones: Sequence[dict], n_frames: int, fps: float) -> list[str]:
    """The phone under each frame ("" where none)."""
    out = [""] * n_frames
    for p in phones:
        first = max(0, int(np.ceil(p["start"] * fps - 1e-9)))
        stop = min(n_frames, int(np.ceil(p["end"] * fps - 1e-9)))
        label = "" if p["phone"] == "SIL" else p["phone"]
        for k in range(first, stop):
            out[k] = label
    return out


def face_frames(animation: FaceAnimation, *, size=(480, 540),
                phones: Sequence[dict] = ()) -> Iterable[np.ndarray]:
    """RGB frames of an animation (a generator; one renderer for all of them)."""
    renderer = FaceRenderer(animation.mesh, animation_bounds(animation), size)
    text = captions(phones, animation.n_frames, animation.fps)
    try:
        for k in range(animation.n_frames):
            yield renderer.frame(animation.vertices[k], text[k])
    finally:
        renderer.close()


def encode(frames: Iterable[np.ndarray], path: Path, fps: float, *,
           audio: Path | None = None, audio_offset: float = 0.0) -> Path:
    """Pipe RGB frames into ffmpeg: ``.mp4`` (H.264 + AAC) or ``.gif``; atomic.

    Parameters
    ----------
    frames : iterable of np.ndarray, each (height, width, 3) uint8
    path : Path
        Target; written as a hidden temporary file beside it, then renamed.
    fps : float
    audio : Path, optional
        Speech to mux in (MP4 only), starting at ``audio_offset`` seconds.

    Raises
    ------
    DataError
        If ffmpeg fails (its last message line), or no frame came.
    """
    from ingest.formats.media import input_args

    path = Path(path)
    kind = path.suffix.lower()
    if kind not in (".mp4", ".gif"):
        raise ParameterError(f"video output must end in .mp4 or .gif, got {path.name!r}")
    check_folder(path)
    frames = iter(frames)
    try:
        first = next(frames)
    except StopIteration:
        raise DataError("nothing to render: the motion has no frames") from None
    height, width = first.shape[:2]
    tmp = _temporary(path, kind)
    cmd = [ffmpeg_exe(), "-nostdin", "-y", "-loglevel", "error", "-f", "rawvideo",
           "-pix_fmt", "rgb24", "-s", f"{width}x{height}", "-r", f"{fps:.6g}", "-i", "-"]
    if kind == ".mp4":
        if audio is not None:
            cmd += ["-ss", f"{audio_offset:.6f}", *input_args(audio), "-map", "0:v", "-map", "1:a",
                    "-c:a", "aac", "-b:a", "128k"]
        cmd += ["-c:v", "libx264", "-preset", "veryfast", "-crf", "20", "-pix_fmt", "yuv420p",
                "-movflags", "+faststart", "-f", "mp4", str(tmp)]
    else:
        cmd += ["-vf", "split[a][b];[a]palettegen=max_colors=128[p];[b][p]paletteuse"
                "=dither=bayer", "-f", "gif", str(tmp)]
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        try:
            proc.stdin.write(np.ascontiguousarray(first).tobytes())
            for image in frames:
                if image.shape[:2] != (height, width):
                    raise ParameterError("frames of different sizes")
                proc.stdin.write(np.ascontiguousarray(image).tobytes())
            proc.stdin.close()
        except BrokenPipeError:
            pass
        err = proc.stderr.read().decode(errors="replace")
        code = proc.wait()
        if code != 0 or not tmp.exists():
            lines = [line for line in err.splitlines() if line.strip()]
            raise DataError(f"ffmpeg could not write {path.name}: "
                            f"{lines[-1] if lines else f'exit status {code}'}")
        os.replace(tmp, path)
    except BaseException:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        tmp.unlink(missing_ok=True)
        # Closing the frames now closes a progress bar wrapped round them; left to the
        # garbage collector it would end its line after the error, on the error's line.
        if hasattr(frames, "close"):
            frames.close()
        raise
    return path


def _temporary(path: Path, suffix: str = "") -> Path:
    """A hidden, unique name beside ``path``: in its folder, so renaming onto it is atomic."""
    return path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp{suffix}"


def place_beside(path: Path, video: Path, *, out: Path | None = None) -> Path:
    """Put ``video`` (the actor) left of the rendered MP4 ``path``, at its height; atomic.

    The sound is the rendered file's if it has any, else the video's; the result ends
    with the shorter of the two (where the last decodable picture of a video cut short
    is, whatever its header says).

    Parameters
    ----------
    path : Path
        The rendered face (``.mp4``).
    video : Path
        The actor's video.
    out : Path, optional
        Where the pair goes (default: over ``path``); written as a hidden temporary file
        beside it, then renamed.

    Raises
    ------
    ParameterError
        If ``path`` or ``out`` is not an ``.mp4``.
    DataError
        If ``video`` is missing or ffmpeg cannot read or write either (its last line).
    """
    from ingest.formats.media import input_args, read_frames

    path, video = Path(path), Path(video)
    out = path if out is None else Path(out)
    for name in (path, out):
        if name.suffix.lower() != ".mp4":
            raise ParameterError(f"--beside needs an .mp4 output, got {name.name!r}")
    if not video.is_file():
        raise DataError(f"video not found: {video}")
    reader = read_frames(path)
    try:
        meta = next(reader)
    finally:
        reader.close()
    height = int(meta["size"][1])
    sound = "1:a" if meta.get("audio_codec") else "0:a?"
    check_folder(out)
    tmp = _temporary(out, ".mp4")
    # hstack's shortest=1: by default it would repeat the shorter input's last picture up
    # to the longer's end (a frozen actor), and -shortest alone only trims the sound. The
    # actor is brought to the face's frame rate: hstack emits a frame whenever either
    # input has one, so 25 fps beside 30 would make a variable rate of about 52.
    cmd = [ffmpeg_exe(), "-nostdin", "-y", "-loglevel", "error", *input_args(video),
           *input_args(path), "-filter_complex",
           f"[0:v]scale=-2:{height},setsar=1,fps={float(meta['fps']):.6g}[a];"
           "[1:v]setsar=1[b];[a][b]hstack=inputs=2:shortest=1[v]",
           "-map", "[v]", "-map", sound, "-shortest", "-c:v", "libx264", "-preset",
           "veryfast", "-crf", "20", "-pix_fmt", "yuv420p", "-c:a", "aac",
           "-movflags", "+faststart", str(tmp)]
    try:
        result = subprocess.run(cmd, capture_output=True, check=False)
        if result.returncode != 0 or not tmp.exists():
            lines = [x for x in result.stderr.decode(errors="replace").splitlines()
                     if x.strip()]
            raise DataError(f"ffmpeg could not put {video.name} beside {out.name}: "
                            f"{lines[-1] if lines else f'exit status {result.returncode}'}")
        os.replace(tmp, out)
    except BaseException:  # a Ctrl-C too: nothing half-written is left beside ``out``
        tmp.unlink(missing_ok=True)
        raise
    return out


def write_obj_frames(animation: FaceAnimation, folder: Path, *, force: bool = False) -> Path:
    """One OBJ per frame (``frame_00000.obj`` ...) in a new folder, built aside and renamed."""
    from db.atomic import replace_dir

    folder = Path(folder)
    if folder.exists() and not force:
        raise DataError(f"{folder} exists (use --force to replace it)")
    check_folder(folder)
    staging = folder.parent / f".{folder.name}.partial-{secrets.token_hex(4)}"
    staging.mkdir()
    try:
        faces = "".join(f"f {a} {b} {c}\n" for a, b, c in (animation.mesh.faces + 1).tolist())
        for k, verts in enumerate(animation.vertices):
            lines = "".join(f"v {x:.4f} {y:.4f} {z:.4f}\n" for x, y, z in verts.tolist())
            (staging / f"frame_{k:05d}.obj").write_text(
                f"# animegraph frame {k}, t = {k / animation.fps:.4f} s, units mm\n"
                + lines + faces)
        replace_dir(staging, folder)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return folder


def curve_frames(motion: Motion, phones: Sequence[dict], *, fps: float = 30.0,
                 size=(960, 540), max_curves: int = 8) -> Iterable[np.ndarray]:
    """Frames of curve motion: the busiest curves over time, phones, a moving cursor.

    The plot is drawn once; each frame only paints the cursor column.
    """
    image, x_of_time = curve_image(motion, phones, size=size, max_curves=max_curves)
    n = max(1, int(np.floor(motion.duration * fps + 1e-9)))
    for k in range(n):
        frame = image.copy()
        x = int(round(x_of_time(k / fps)))
        frame[:, max(0, x - 1):x + 1] = (220, 40, 40)
        yield frame


def curve_image(motion: Motion, phones: Sequence[dict], *, size=(960, 540),
                max_curves: int = 8, path: Path | None = None):
    """Plot the busiest curves with phone labels; the RGB image and a time-to-column map."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    width, height = (int(s) - int(s) % 2 for s in size)
    values = np.asarray(motion.values, dtype=np.float64)
    spread = np.nanstd(values, axis=0)
    moving = spread > 1e-6 * max(float(np.nanmax(spread)), 1e-12)
    chosen = [c for c in np.argsort(-spread)[:max_curves] if moving[c]] or [0]
    t = np.arange(motion.n_frames) / motion.fps
    fig = Figure(figsize=(width / 100, height / 100), dpi=100)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.07, 0.12, 0.74, 0.8))
    for c in chosen:
        ax.plot(t, values[:, c], lw=1.2, label=motion.names[c])
    ax.set_xlim(0, motion.duration)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("curve value")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, frameon=False)
    for k, p in enumerate(phones):
        ax.axvline(p["start"], color="0.85", lw=0.5, zorder=0)
        if p["phone"] != "SIL":
            ax.text(0.5 * (p["start"] + p["end"]), 1.01 if k % 2 else 1.045, p["phone"],
                    ha="center", fontsize=6, transform=ax.get_xaxis_transform())
    canvas.draw()
    image = np.asarray(canvas.buffer_rgba())[..., :3].copy()
    if path is not None:
        from db.atomic import atomic_write

        with atomic_write(path) as handle:
            fig.savefig(handle, format="png", dpi=100)
    bbox = ax.get_window_extent()
    x0, x1 = bbox.x0, bbox.x1

    def x_of_time(seconds: float) -> float:
        return x0 + (x1 - x0) * seconds / max(motion.duration, 1e-9)

    return image, x_of_time


def render_motion(motion: Motion, out: Path, *, deformer: Deformer | None = None,
                  audio: Path | None = None, fps: float | None = None,
                  phones: Sequence[dict] = (), size: tuple[int, int] | None = None,
                  force: bool = False,
                  progress: Callable[[int], Callable] | None = None,
                  beside: Path | None = None) -> Path:
    """Render ``motion`` to ``out`` by its extension (see :data:`FORMATS`).

    Parameters
    ----------
    deformer : Deformer, optional
        Mesh and marker map for point motion; None renders the channels as curves.
    audio : Path, optional
        Speech muxed into an MP4: a WAV or a video's sound track, read first by
        :func:`ingest.formats.media.read_audio`, whose errors are the ones raised.
    fps : float, optional
        Frame rate of the video (default 30; 20 for a GIF) or of the glTF / OBJ frames
        (default the motion's).
    phones : sequence of dict
        ``phone``, ``start``, ``end``: captions, or labels on a curve plot.
    size : (width, height), optional
        Frame size of an MP4, GIF or PNG (default 480 x 540 for a face, 240 x 270 for
        its GIF; curves 960 x 540, their GIF 640 x 360); not for glTF or OBJ frames.
    beside : Path, optional
        The actor's video, put left of the face (MP4 only, :func:`place_beside`); checked
        before anything is rendered. The result ends with the shorter of the two; a
        warning is logged when that is the video.

    Raises
    ------
    ParameterError
        If ``out``'s extension is not one of :data:`FORMATS`, ``audio`` or ``beside``
        is given for another output than an MP4, or ``size`` for a glTF or OBJ frames.
    DataError
        If ``audio`` or ``beside`` cannot be read, or writing fails; ``out`` is then left
        as it was.
    """
    out = Path(out)
    kind = out.suffix.lower()
    if kind not in FORMATS:
        raise ParameterError(f"output must end in .mp4, .gif, .glb or .png, or be a folder "
                             f"for OBJ frames; got {out.name!r}")
    if kind == "" and out.exists() and not force:
        raise DataError(f"{out} exists (use --force to replace it)")
    if kind != "" and out.is_dir():
        raise DataError(f"{out} is a folder")
    check_folder(out)  # before the frames are drawn, not when they are written
    video_fps = fps or (20.0 if kind == ".gif" else 30.0)
    for option, given in (("--beside", beside), ("--audio", audio)):
        if given is not None and kind != ".mp4":
            raise ParameterError(f"{option} needs an .mp4 output, got {out.name!r}")
    if size is not None and kind in (".glb", ""):
        raise ParameterError(f"--size needs an .mp4, .gif or .png output, got {out.name!r}")
    if audio is not None:
        from ingest.formats.media import read_audio

        # Read by the reader synth uses: its one line (no audio track, non-finite or
        # corrupt samples) now, not ffmpeg's internals halfway through the frames.
        read_audio(audio)
    if beside is not None:
        _check_beside(Path(beside), motion.duration, video_fps)
    arkit = deformer is None and is_arkit(motion.names)
    if deformer is None and not arkit:
        if kind in (".glb", ""):
            raise ParameterError("curve motion (no marker geometry) cannot become a mesh "
                                 "animation: render .mp4, .gif or .png")
        if kind == ".png":
            curve_image(motion, phones, path=out, size=size or (960, 540))
            return out
        frames = curve_frames(motion, phones, fps=video_fps,
                              size=size or ((640, 360) if kind == ".gif" else (960, 540)))
        return _video(frames, out, video_fps, audio=audio, beside=beside)
    if kind in (".mp4", ".gif", ".png"):
        animation = _animation(motion, deformer, video_fps)
        size = size or ((240, 270) if kind == ".gif" else (480, 540))
        if kind == ".png":
            return _still(animation, out, phones, size)
        frames = face_frames(animation, size=size, phones=phones)
        if progress is not None:
            frames = progress(animation.n_frames)(frames)
        return _video(frames, out, video_fps, audio=audio, beside=beside)
    animation = _animation(motion, deformer, fps)
    if kind == ".glb":
        from animegraph.face.gltf import write_arkit_glb, write_glb

        if arkit:
            return write_arkit_glb(animation, arkit_weights(motion, animation.fps), out)
        return write_glb(animation, out)
    return write_obj_frames(animation, out, force=force)


def _check_beside(video: Path, duration: float, fps: float) -> None:
    """Refuse a video with no decodable picture; warn if it is shorter than the motion."""
    from ingest.formats.media import video_length

    length = video_length(video)
    # Within a frame of the motion is the same length (a container rounds its duration).
    if length < duration - 1.0 / fps:
        logger.warning("%s holds %.2f s of video, the motion %.2f s: the result ends at "
                       "%.2f s", video.name, length, duration, length)


def _video(frames: Iterable[np.ndarray], out: Path, fps: float, *, audio: Path | None,
           beside: Path | None) -> Path:
    """:func:`encode` to ``out``; with ``beside``, the face into a hidden folder beside
    ``out`` and then the pair onto ``out`` (:func:`place_beside`), so a failure at either
    step leaves ``out`` as it was."""
    if beside is None:
        return encode(frames, out, fps, audio=audio)
    check_folder(out)
    staging = _temporary(out)
    staging.mkdir()
    try:
        # The face keeps out's name inside the folder, so ffmpeg's errors name the output.
        face = encode(frames, staging / out.name, fps, audio=audio)
        return place_beside(face, beside, out=out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _animation(motion: Motion, deformer: Deformer | None, fps: float | None) -> FaceAnimation:
    """Point motion through the deformer; ARKit curves (no deformer) on the canonical face."""
    if deformer is None:
        return arkit_animation(motion, fps=fps)
    return animate(motion, deformer, fps=fps)


def _still(animation: FaceAnimation, out: Path, phones, size) -> Path:
    """A PNG of the frame where the mouth is widest open (the face's extremes show)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from db.atomic import atomic_write

    spread = np.linalg.norm(animation.local - animation.mesh.vertices[None], axis=2).sum(1)
    k = int(np.argmax(spread))
    renderer = FaceRenderer(animation.mesh, animation_bounds(animation), size)
    try:
        image = renderer.frame(animation.vertices[k], captions(phones, animation.n_frames,
                                                               animation.fps)[k])
    finally:
        renderer.close()
    with atomic_write(out) as handle:
        plt.imsave(handle, image, format="png")
    return out


def deformer_for(names: Sequence[str], *, mesh_path: Path | None = None,
                 map_path: Path | None = None, rest_frame: np.ndarray | None = None
                 ) -> Deformer | None:
    """The deformer for motion with channels ``names`` (None for curve motion).

    Default: the canonical mesh, with the corpus' markers or ``lm<i>`` landmarks mapped
    on its vertices; a custom ``mesh_path`` needs a ``map_path``.

    Raises
    ------
    DataError
        On an unreadable mesh or map, or a map naming markers the motion lacks.
    """
    from animegraph.face.mesh import (
        canonical_mesh,
        default_marker_map,
        load_mesh,
        read_marker_map,
    )
    from animegraph.motion.files import point_labels

    labels = point_labels(names)
    if not labels:
        if mesh_path is not None or map_path is not None:
            raise DataError("the motion has no x/y/z point channels to put on a mesh")
        return None
    if mesh_path is not None and map_path is None:
        raise ParameterError("--mesh needs --marker-map (which marker sits on which vertex)")
    mesh = load_mesh(mesh_path) if mesh_path is not None else canonical_mesh()
    markers: MarkerMap = (read_marker_map(map_path, mesh) if map_path is not None
                          else default_marker_map(labels))
    missing = [lab for lab in markers.labels if lab not in set(labels)]
    if missing:
        raise DataError(f"the motion's channels do not match the mesh's marker map: "
                        f"{len(missing)} of its {markers.n_markers} markers are missing "
                        f"({', '.join(missing[:4])}{' ...' if len(missing) > 4 else ''})")
    return Deformer.build(mesh, markers, rest=rest_frame)
