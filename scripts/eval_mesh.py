"""How well §7's RBF-with-regions deformation recovers the whole face from 72 markers.

The synthetic corpus' face rig is posed on every vertex of the canonical mesh (the
truth) and on the markers (the input) for a spoken, expressive sentence; the markers
are carried to the mesh by :class:`animegraph.face.mesh.Deformer` and compared with the
truth: RMS vertex error over the face and around the mouth, and the error of the inner
lip gap between two vertices that are not markers (82 upper, 87 lower) — what smears
when the lips are interpolated together.

    python scripts/eval_mesh.py
"""

from __future__ import annotations

import numpy as np

from animegraph.face.mesh import Deformer, canonical_mesh, default_marker_map
from ingest.corpus import face
from ingest.corpus.synthetic import ClipSpec, CorpusConfig, synthesize_clip


def main() -> None:
    config = CorpusConfig(marker_noise_mm=0.0, dropouts_per_second=0.0)
    spec = ClipSpec(clip_id="mesh_eval", sentence_id="x", emotion="happy", variation=1,
                    text="Bob moved the warm vase away, and we laughed.", speaker="synth01",
                    seed=5)
    clip = synthesize_clip(spec, config)
    mesh = canonical_mesh()
    markers = default_marker_map([m[0] for m in face.MARKERS])
    truth = face.FaceRig.for_points(mesh.vertices).pose(clip.controls)
    points = face.FaceRig.for_points(mesh.vertices[markers.vertices]).pose(clip.controls)
    mouth = np.abs(mesh.vertices[:, 1] - (-42.7)) < 12.0
    gap_true = np.linalg.norm(truth[:, 82] - truth[:, 87], axis=1)
    print(f"{clip.spec.text!r} ({spec.emotion}), {len(points)} frames at {config.fps:g} fps; "
          f"true inner-lip gap {gap_true.min():.1f}-{gap_true.max():.1f} mm")
    print("| deformation | RMS vertex error (mm) | around the mouth (mm) | max (mm) | "
          "lip-gap error mean / max (mm) |")
    print("|---|---|---|---|---|")
    cases = [("regions, blend band 6 mm (default)", {}),
             ("regions, blend band 12 mm", {"band_mm": 12.0}),
             ("one interpolant, no regions", {"regions": False})]
    for name, kwargs in cases:
        out = Deformer.build(mesh, markers, **kwargs).deform(points)
        err = np.linalg.norm(out - truth, axis=-1)
        gap = np.abs(np.linalg.norm(out[:, 82] - out[:, 87], axis=1) - gap_true)
        print(f"| {name} | {np.sqrt((err ** 2).mean()):.2f} | "
              f"{np.sqrt((err[:, mouth] ** 2).mean()):.2f} | {err.max():.2f} | "
              f"{gap.mean():.2f} / {gap.max():.2f} |")


if __name__ == "__main__":
    main()
