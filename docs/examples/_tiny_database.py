"""The tiny corpus and database the gallery's examples share (not an example itself).

``plot_01_database.py`` shows how they are built; the other examples call
:func:`tiny_database`, which builds them the same way if that example has not run.
"""

from pathlib import Path

from animegraph import __version__
from db.store import is_database
from ingest.cache import cache_dir
from ingest.corpus.synthetic import CorpusConfig

#: The test suite's tiny corpus: 5 sentences, 3 of them in all five emotions, 2 takes each.
CONFIG = CorpusConfig(sentences=5, parallel=3, variations=2, seed=7)


def gallery_folder() -> Path:
    """Where the corpus (``corpus/``) and database (``tiny.db/``) are kept."""
    return cache_dir() / f"gallery-{__version__}"


def tiny_database() -> Path:
    """The tiny database's folder, built on first use (about 30 s on one core)."""
    from ingest.corpus.synthetic import generate_corpus
    from ingest.pipeline import ingest

    folder = gallery_folder()
    db_path = folder / "tiny.db"
    if not is_database(db_path):
        generate_corpus(folder / "corpus", CONFIG, workers=1, force=True)
        ingest([folder / "corpus"], db_path, workers=1)
    return db_path
