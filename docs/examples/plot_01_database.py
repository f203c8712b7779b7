"""
Build a tiny motion database
============================

Generate a tiny synthetic corpus (eSpeak NG speech with exact phone timing, and facial
marker motion made by the corpus' face model in five emotions), ingest it into a motion
database, and plot how many *animes* (phoneme instances) the database holds of each
phone in each emotion: what the Anime Graph search can choose from.

The command line does the same with ``animegraph corpus synth`` and ``animegraph ingest``.
"""

# %%
# The corpus
# ----------
# :class:`~ingest.corpus.synthetic.CorpusConfig` sets its size: here 5 sentences, 3 of
# them spoken in all five emotions (the parallel sentences the emotion mapping learns
# from), 2 takes of each. The files go into the gallery's folder in the user's cache.
from _tiny_database import CONFIG, gallery_folder

from ingest.corpus.synthetic import generate_corpus

folder = gallery_folder()
summary = generate_corpus(folder / "corpus", CONFIG, workers=1, force=True)
print(f"{summary.n_clips} clips in {folder / 'corpus'}")

# %%
# The database
# ------------
# :func:`~ingest.pipeline.ingest` reads every clip, cuts it into phoneme-long animes,
# decomposes the motion into independent components and learns the emotion model. A
# second run skips the clips it already holds.
from ingest.pipeline import ingest

report = ingest([folder / "corpus"], folder / "tiny.db", workers=1)
print(report.lines()[0])

# %%
# What it holds
# -------------
# The tables are Parquet; :func:`db.sql.query` runs read-only SQL over them (the
# ``animegraph sql`` command).
import matplotlib.pyplot as plt
import numpy as np

from db.sql import query
from db.store import Database

db = Database.open(folder / "tiny.db")
table = query(db, "SELECT phoneme, emotion, count(*) AS n FROM animes "
                  "WHERE phoneme <> 'SIL' GROUP BY ALL").to_pydict()
phones = sorted(set(table["phoneme"]))
emotions = sorted(set(table["emotion"]))
counts = np.zeros((len(emotions), len(phones)), dtype=int)
for phone, emotion, n in zip(table["phoneme"], table["emotion"], table["n"], strict=True):
    counts[emotions.index(emotion), phones.index(phone)] = n
order = np.argsort(-counts.sum(axis=0), kind="stable")

fig, ax = plt.subplots(figsize=(10, 3.2), layout="constrained")
image = ax.imshow(counts[:, order], cmap="viridis", aspect="auto")
ax.set_xticks(range(len(phones)), [phones[i] for i in order], rotation=90, fontsize=8)
ax.set_yticks(range(len(emotions)), emotions)
ax.set_title(f"animes per phone and emotion ({counts.sum()} besides silence)")
fig.colorbar(image, ax=ax, label="animes")
plt.show()

# %%
# Phones the sentences never say have no animes: synthesis falls back on animes of the
# same viseme class. A real database is built the same way from captured clips; see the
# user guide.
print(f"{len(phones)} of the 39 phones occur; {db.manifest['n_animes']} animes in all, "
      "with silence")
