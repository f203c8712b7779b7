"""
Synthesize a line from eSpeak speech
====================================

Speak a sentence the corpus does not contain with eSpeak NG, in the happy voice of the
synthetic corpus, and synthesize facial motion for it from the tiny database: the Anime
Graph search picks one anime per phone (Cao et al. 2005, §4.2), then the motion is
time-warped, blended at jumps and smoothed (§4.3). The plot shows the speech, its phones
and three mouth and brow measures of the motion.

``animegraph synth speech.wav --text "..." --emotion happy -o line.c3d`` does the same
from a recording; ``animegraph batch`` speaks lines with eSpeak NG as here.
"""

# %%
# Speech with exact phone timing
# ------------------------------
# :func:`~ingest.speech.espeak.speak` returns the audio and the phones eSpeak NG spoke,
# so no alignment is needed.
from _tiny_database import tiny_database

from ingest.corpus.emotions import style
from ingest.speech.espeak import speak

utterance = speak("Would you like to hear how a brave robot learned to whistle?",
                  style("happy").voice)
print(f"{utterance.duration:.2f} s, {len(utterance.phones)} phones:",
      " ".join(p.phone for p in utterance.phones))

# %%
# Motion from the database
# ------------------------
# :meth:`Model.load <animegraph.synthesis.Model.load>` reads what synthesis needs from the
# database once; :func:`~animegraph.synthesis.synthesize` runs the pipeline. The first
# synthesis on a machine compiles the search kernels (about a minute, cached after).
from animegraph.synthesis import Model, synthesize
from ingest.formats.phones_csv import Segment

model = Model.load(tiny_database())
labels = [Segment(p.phone, p.start, p.end) for p in utterance.phones]
line = synthesize(model, utterance.audio, utterance.sample_rate, labels=labels,
                  emotion="happy")
print(f"motion {line.motion.shape} at {line.fps:g} fps; "
      f"{line.result.n_jumps} jump matches; {line.timings['total_s']:.2f} s")

# %%
# The plot
# --------
# :func:`~animegraph.motion.measures.measures` turns marker motion into distances in mm.
import matplotlib.pyplot as plt
import numpy as np

from animegraph.motion.measures import measures

time_audio = np.arange(len(utterance.audio)) / utterance.sample_rate
time_motion = np.arange(len(line.motion)) / line.fps
found = measures(line.motion, model.names)

fig, axes = plt.subplots(1 + len(found), 1, figsize=(9, 6), sharex=True,
                         layout="constrained")
axes[0].plot(time_audio, utterance.audio, color="0.4", linewidth=0.5)
for phone in utterance.phones:
    axes[0].axvline(phone.start, color="0.8", linewidth=0.5)
    if phone.phone != "SIL":
        axes[0].text((phone.start + phone.end) / 2, 0.9, phone.phone, fontsize=7,
                     ha="center", transform=axes[0].get_xaxis_transform())
axes[0].set_ylabel("speech")
for ax, (label, values) in zip(axes[1:], found, strict=True):
    ax.plot(time_motion, values, color="tab:red")
    ax.set_ylabel(label, fontsize=8)
axes[-1].set_xlabel("time (s)")
fig.suptitle("synthesized from the tiny database (happy)")
plt.show()
