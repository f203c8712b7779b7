"""
Change a motion's emotion
=========================

The database splits motion into independent components that carry speech and ones that
carry emotion (Cao et al. 2005, §5.1), and learns an RBF mapping of the emotion
components between each pair of emotions from the sentences recorded in both (§5.2).
Here a neutral take is mapped into happy, sad and angry: the lips still say the same
words, while the brows and mouth corners change.

``animegraph map-emotion IN --to happy -o OUT`` does the same to a motion file;
``animegraph synth --emotion`` applies it during synthesis.
"""

# %%
# A neutral take, in the database's channels
# ------------------------------------------
import matplotlib.pyplot as plt
import numpy as np
from _tiny_database import gallery_folder, tiny_database

from animegraph.emotion.control import map_motion
from animegraph.motion.measures import measures
from animegraph.synthesis import Model, read_database_motion

model = Model.load(tiny_database())
print("emotion components:", model.emotion_model.split.emotion_components,
      "speech components:", model.emotion_model.split.speech_components)
take = gallery_folder() / "corpus" / "clips" / "s0001_neutral_1.c3d"
neutral, fps = read_database_motion(take, model)

# %%
# Mapped into three emotions
# --------------------------
# :func:`~animegraph.emotion.control.map_motion` maps the emotion components and keeps
# the speech components and the head's rigid motion.
mapped = {"neutral": neutral}
for target in ("happy", "sad", "angry"):
    mapped[target] = map_motion(model, neutral, "neutral", target, fps=fps)

time = np.arange(len(neutral)) / fps
labels = [label for label, _ in measures(neutral, model.names)]
fig, axes = plt.subplots(len(labels), 1, figsize=(9, 6), sharex=True, layout="constrained")
for emotion, values in mapped.items():
    for ax, (label, series) in zip(axes, measures(values, model.names), strict=True):
        ax.plot(time, series, label=emotion, linewidth=1.2 if emotion == "neutral" else 0.9)
        ax.set_ylabel(label, fontsize=8)
axes[0].legend(ncol=4, fontsize=8)
axes[-1].set_xlabel("time (s)")
fig.suptitle("one neutral take mapped into other emotions")
plt.show()

# %%
# On the face
# -----------
# The same frame of each, drawn on the mesh.
from animegraph.face.animation import animate, animation_bounds
from animegraph.face.render import FaceRenderer, deformer_for
from animegraph.motion.files import Motion

deformer = deformer_for(model.names)
frame = int(np.argmax(measures(neutral, model.names)[0][1]))
animations = {emotion: animate(Motion(values[frame:frame + 1], model.names, fps), deformer)
              for emotion, values in mapped.items()}
bounds = np.stack([animation_bounds(a) for a in animations.values()])
renderer = FaceRenderer(deformer.mesh, np.stack([bounds[:, 0].min(0), bounds[:, 1].max(0)]),
                        size=(240, 270))
fig, axes = plt.subplots(1, len(animations), figsize=(9, 3.2), layout="constrained")
for ax, (emotion, animation) in zip(axes, animations.items(), strict=True):
    ax.imshow(renderer.frame(animation.vertices[0]))
    ax.set_title(emotion)
    ax.set_axis_off()
renderer.close()
plt.show()
