"""Time rendering 10 s of marker motion at 30 fps to MP4 (target: <= 30 s on 2 cores).

The motion is the synthetic corpus' face rig at 120 fps (speech-like jaw, smile, blinks,
head turns) written as C3D with 10 s of speech-band audio; the timing covers what
``animegraph render take.c3d --audio take.wav -o take.mp4`` does: read the C3D, build
the §7 deformer, carry the motion onto the mesh, draw every frame and encode H.264 +
AAC through ffmpeg. GLB and GIF timings are printed beside it.

    python scripts/bench_render.py [--seconds 10] [--fps 30] [--size 480x540]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from animegraph.face.animation import animate
from animegraph.face.gltf import write_glb
from animegraph.face.render import deformer_for, encode, face_frames
from animegraph.motion.files import read_motion
from ingest.corpus import face
from ingest.formats.c3d import MarkerData, write_c3d
from ingest.formats.wav import write_wav


def make_take(folder: Path, seconds: float, fps: float = 120.0) -> tuple[Path, Path]:
    n = int(seconds * fps)
    t = np.arange(n) / fps
    rng = np.random.default_rng(0)
    controls = np.zeros((n, len(face.CONTROLS)))
    col = face.CONTROLS.index
    controls[:, col("jaw_open")] = np.clip(0.5 + 0.5 * np.sin(2 * np.pi * 4.3 * t)
                                           + 0.2 * rng.standard_normal(n).cumsum() / 60, 0, 1)
    controls[:, col("lip_round")] = 0.5 + 0.5 * np.sin(2 * np.pi * 1.7 * t)
    controls[:, col("smile")] = 0.5 + 0.5 * np.sin(2 * np.pi * 0.2 * t)
    controls[:, col("blink")] = np.exp(-(((t % 3.0) - 1.5) / 0.06) ** 2)
    controls[:, col("head_yaw")] = 10 * np.sin(2 * np.pi * 0.3 * t)
    controls[:, col("head_pitch")] = 4 * np.sin(2 * np.pi * 0.5 * t)
    points = face.FaceRig.for_points(face.marker_rest()).pose(controls)
    labels = tuple(m[0] for m in face.MARKERS)
    motion = folder / "take.c3d"
    write_c3d(motion, MarkerData(points=points, labels=labels, rate=fps))
    sr = 16000
    ts = np.arange(int(seconds * sr)) / sr
    audio = 0.2 * np.sin(2 * np.pi * 150 * ts) * (0.5 + 0.5 * np.sin(2 * np.pi * 4.3 * ts))
    wav = folder / "take.wav"
    write_wav(wav, audio, sr)
    return motion, wav


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--size", default="480x540")
    args = parser.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        motion_path, wav = make_take(folder, args.seconds)
        t0 = time.perf_counter()
        motion = read_motion(motion_path)
        t1 = time.perf_counter()
        deformer = deformer_for(motion.names)
        t2 = time.perf_counter()
        animation = animate(motion, deformer, fps=args.fps)
        t3 = time.perf_counter()
        out = encode(face_frames(animation, size=size), folder / "take.mp4", args.fps,
                     audio=wav)
        t4 = time.perf_counter()
        mp4_mb = out.stat().st_size / 1e6
        glb_start = time.perf_counter()
        glb = write_glb(animate(motion, deformer), folder / "take.glb")
        glb_s = time.perf_counter() - glb_start
        gif_start = time.perf_counter()
        gif_anim = animate(motion, deformer, fps=20)
        encode(face_frames(gif_anim, size=(240, 270)), folder / "take.gif", 20)
        gif_s = time.perf_counter() - gif_start
        total = t4 - t0
        frames = animation.n_frames
        print(f"cores: {os.cpu_count()}; motion: {args.seconds:g} s at {motion.fps:g} fps, "
              f"{len(deformer.markers.labels)} markers -> {deformer.mesh.n_vertices} vertices")
        print(f"MP4 {size[0]}x{size[1]} at {args.fps:g} fps ({frames} frames, with audio): "
              f"{total:.2f} s total = read {t1 - t0:.3f} + deformer {t2 - t1:.3f} + "
              f"deform {t3 - t2:.3f} + draw & encode {t4 - t3:.2f} "
              f"({1000 * (t4 - t3) / frames:.1f} ms/frame); {mp4_mb:.2f} MB; "
              f"{'meets' if total <= 30 else 'misses'} the 30 s target")
        print(f"GLB (all {motion.n_frames} frames, morph targets): {glb_s:.2f} s, "
              f"{glb.stat().st_size / 1e6:.2f} MB")
        print(f"GIF 240x270 at 20 fps: {gif_s:.2f} s")


if __name__ == "__main__":
    main()
