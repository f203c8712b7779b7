"""The search kernels' cache is keyed by the sources of every file holding kernels."""

from __future__ import annotations

import os
import shutil
import time
from importlib import import_module
from pathlib import Path

from animegraph.search import jit

ROOM = Path(jit.__file__).parent


def _copy_room(dest: Path) -> Path:
    dest.mkdir()
    for path in ROOM.glob("*.py"):
        shutil.copy(path, dest / path.name)
    return dest


def test_an_edit_to_a_kernel_in_another_file_changes_the_cache_folder(tmp_path):
    # exact.py's cached kernels have kdtree.py's compiled into them: numba checked only
    # exact.py's own source, and ran the old tree after kdtree.py changed.
    room = _copy_room(tmp_path / "search")
    key = jit.cache_key(room)
    assert key == jit.cache_key(ROOM) and key.startswith(__import__("animegraph").__version__)
    kdtree = room / "kdtree.py"
    kdtree.write_text(kdtree.read_text().replace("LEAF = 16", "LEAF = 8"))
    assert jit.cache_key(room) != key
    # A file without kernels does not throw the compiled kernels away.
    solve = room / "solve.py"
    kdtree.write_text((ROOM / "kdtree.py").read_text())
    solve.write_text(solve.read_text() + "\n# an edit\n")
    assert jit.cache_key(room) == key


def test_every_file_holding_kernels_is_in_the_key_and_caches_in_the_keyed_folder():
    from numba.core.dispatcher import Dispatcher

    folder = jit.cache_folder()
    assert folder is not None and folder.name == f"numba-{jit.cache_key()}"
    found = set()
    for path in ROOM.glob("*.py"):
        module = import_module(f"animegraph.search.{path.stem}")
        for value in vars(module).values():
            if isinstance(value, Dispatcher) and value.__module__ == module.__name__:
                found.add(path.name)
                index = Path(value._cache._cache_file._index_path)
                assert folder in index.parents, (value, index)
    assert found and found | {"jit.py"} == set(jit.KERNEL_FILES)


def test_a_new_key_prunes_the_folders_unused_for_a_day(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    old, recent = tmp_path / "numba-0.0.9-old", tmp_path / "numba-0.0.9-recent"
    other = tmp_path / "librosa_1234"  # not ours: left alone
    for folder in (old, recent, other):
        (folder / "sub").mkdir(parents=True)
    day_ago = time.time() - 2 * 24 * 3600
    os.utime(old, (day_ago, day_ago))
    os.utime(other, (day_ago, day_ago))
    monkeypatch.setattr(jit, "cache_key", lambda folder=None: "0.1.0-new")
    jit.cache_folder.cache_clear()
    try:
        assert jit.cache_folder() == tmp_path / "numba-0.1.0-new"
    finally:
        jit.cache_folder.cache_clear()
    assert not old.exists() and recent.is_dir() and other.is_dir()

