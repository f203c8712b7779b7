"""
Put motion on the face
======================

Carry a recorded clip's marker motion onto the canonical face mesh by RBF scattered-data
interpolation (Cao et al. 2005, §7) and draw a few of its frames: the mouth closed, and
opened at the clip's widest moments.

``animegraph render MOTION -o face.mp4`` writes the whole clip as a video (or a GIF, a
PNG, glTF, OBJ frames) with the speech muxed in.
"""

# %%
# A clip of the corpus
# --------------------
# :func:`~animegraph.motion.files.read_motion` reads C3D, channel CSV or NPZ into a
# :class:`~animegraph.motion.files.Motion` of shape ``(n_frames, n_channels)``.
import matplotlib.pyplot as plt
import numpy as np
from _tiny_database import gallery_folder, tiny_database

from animegraph.motion.files import read_motion
from animegraph.motion.measures import measure

tiny_database()  # makes sure the corpus is there
motion = read_motion(gallery_folder() / "corpus" / "clips" / "s0001_happy_1.c3d")
label, opening = measure(motion.values, motion.names)
print(f"{motion.n_frames} frames at {motion.fps:g} fps, {len(motion.names)} channels")

# %%
# Onto the mesh
# -------------
# :func:`~animegraph.face.render.deformer_for` maps the markers onto the mesh's
# vertices; :func:`~animegraph.face.animation.animate` moves every vertex, here at 30
# frames a second; :class:`~animegraph.face.render.FaceRenderer` draws a frame.
from animegraph.face.animation import animate, animation_bounds
from animegraph.face.render import FaceRenderer, deformer_for

deformer = deformer_for(motion.names)
animation = animate(motion, deformer, fps=30)
renderer = FaceRenderer(deformer.mesh, animation_bounds(animation), size=(240, 270))

# The most closed frame, and the three most open ones at least 0.3 s apart.
step = motion.fps / animation.fps
open_30 = opening[np.minimum((np.arange(animation.n_frames) * step).astype(int),
                             len(opening) - 1)]
picked = [int(np.argmin(open_30))]
for frame in np.argsort(-open_30):
    if all(abs(int(frame) - p) >= 9 for p in picked):
        picked.append(int(frame))
    if len(picked) == 4:
        break
picked.sort()

fig, axes = plt.subplots(1, len(picked), figsize=(9, 3.2), layout="constrained")
for ax, frame in zip(axes, picked, strict=True):
    ax.imshow(renderer.frame(animation.vertices[frame]))
    ax.set_title(f"{frame / animation.fps:.2f} s, {label.split(' (')[0]} "
                 f"{open_30[frame]:.1f} mm", fontsize=8)
    ax.set_axis_off()
renderer.close()
plt.show()
