"""A database ready for its first synth: ``ingest`` and ``warmup`` fit the default guides
(:mod:`animegraph.apps.prepare`), so an audio-only ``synth`` fits nothing itself."""

from __future__ import annotations

import shutil

import pytest

from animegraph.apps.cli import main
from animegraph.apps.prepare import unfitted_note
from animegraph.baselines.stored import load_forward, model_path, unfit_reason
from animegraph.synthesis.path import AUDIO_ONLY_GUIDE

GUIDES = AUDIO_ONLY_GUIDE.split("+")


def _decided(db) -> dict[str, bool]:
    """Per default guide: whether the database has it stored or knows why it has not."""
    return {name: load_forward(db, name) is not None or unfit_reason(db, name) is not None
            for name in GUIDES}


@pytest.fixture()
def db_copy(tiny_db, tmp_path):
    path = tmp_path / "db"
    shutil.copytree(tiny_db[0], path)
    shutil.rmtree(path / "baselines", ignore_errors=True)  # as ingest left it
    return path


def test_warmup_fits_the_guides_once_and_synth_then_fits_nothing(db_copy, tiny_corpus,
                                                                 tmp_path, capsys):
    assert _decided(db_copy) == dict.fromkeys(GUIDES, False)
    note = unfitted_note(db_copy)  # what the demo says of the database it built
    assert all(f"{name} about " in note for name in GUIDES) and "animegraph warmup" in note
    assert main(["warmup", "--db", str(db_copy)]) == 0
    err = capsys.readouterr().err
    for name in GUIDES:
        assert f"fitting the {name} guide of audio-only synth (about " in err
    assert _decided(db_copy) == dict.fromkeys(GUIDES, True)
    stored = {name: model_path(db_copy, name).stat().st_mtime_ns for name in GUIDES
              if model_path(db_copy, name).is_file()}
    assert stored  # the tiny database has enough for at least one
    assert unfitted_note(db_copy) is None
    assert main(["warmup", "--db", str(db_copy)]) == 0  # nothing left to do
    out = capsys.readouterr()
    assert "fitting" not in out.err and "is ready for synth" in out.out
    wav = tmp_path / "speech.wav"  # away from its phone labels: speech alone
    shutil.copy(tiny_corpus / "clips" / "s0001_angry_1.wav", wav)
    assert main(["synth", str(wav), "--db", str(db_copy), "-o", str(tmp_path / "m.npz")]) == 0
    err = capsys.readouterr().err
    assert "(recognized)" in err
    assert not [name for name in GUIDES if f"fitting {name} on" in err]
    assert {name: model_path(db_copy, name).stat().st_mtime_ns for name in stored} == stored


def test_warmup_needs_a_database(tmp_path, capsys):
    assert main(["warmup", "--db", str(tmp_path / "none")]) == 1
    assert "no database at" in capsys.readouterr().err


@pytest.mark.parametrize("prepare", [True, False])
def test_ingest_prepares_the_database_unless_told_not_to(tiny_corpus, tmp_path, capsys,
                                                         prepare, monkeypatch):
    from ingest.cache import CACHE_ENV

    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    src = tmp_path / "src"
    src.mkdir()
    for path in sorted((tiny_corpus / "clips").glob("s0001_*_1.*")):
        shutil.copy(path, src)
    db = tmp_path / "db"
    argv = ["ingest", str(src), "--db", str(db), "--quiet"]
    assert main(argv + ([] if prepare else ["--no-prepare"])) == 0
    assert _decided(db) == dict.fromkeys(GUIDES, prepare)
    # ppg-ridge's fit kept what hama heard of each clip (the refit after the next ingest
    # hears only the clips it adds); ingest itself, given the phones, heard none.
    kept = list((tmp_path / "cache" / "phones").glob("*.npy"))
    assert len(kept) == (len(list(src.glob("*.wav"))) if prepare else 0)


def test_guides_fitted_beside_this_process_are_stored_then_nothing_is_left(db_copy):
    from animegraph.apps.prepare import GuideFit

    assert unfitted_note(db_copy) is not None
    said = []
    fit = GuideFit.start(db_copy, said.append)  # spawned, under the database's writer lock
    assert fit is not None
    assert fit.wait(said.append)
    assert all(any(line.startswith(f"guides: fitting the {name} guide") for line in said)
               for name in GUIDES)
    assert _decided(db_copy) == dict.fromkeys(GUIDES, True)
    assert unfitted_note(db_copy) is None and GuideFit.start(db_copy) is None


def test_guides_fit_stopped_leaves_the_database_as_it_was(db_copy):
    import threading

    from animegraph.apps.prepare import GuideFit

    inside = threading.Event()
    fit = GuideFit.start(db_copy, lambda line: "guides: fitting the" in line and inside.set())
    while not inside.wait(0.1) and fit._process.is_alive():
        pass  # until the child is inside a fit
    assert inside.is_set()
    fit.stop()  # a Ctrl-C to the child, whose writes are atomic
    assert not fit.wait()
    for name in GUIDES:  # each guide stored whole, or not at all
        assert load_forward(db_copy, name) is not None or not model_path(db_copy, name).exists()
    assert not list(db_copy.rglob(".*.tmp"))  # no half-written file left behind


def test_ppg_ridge_estimate_counts_only_the_speech_hama_hears_again(db_copy):
    from animegraph.apps import prepare
    from db.store import Database

    database = Database.open(db_copy)
    assert prepare._minutes_without_posteriors(database) == 0  # stored for every clip
    minutes = float(database.manifest["duration_s"]) / 60
    stored = prepare.PPG_RIDGE_STORED_CPU_S_PER_MIN * minutes
    assert prepare.fit_estimate(db_copy, "ppg-ridge") == (
        f"about {max(stored, 1):.0f} s on a quiet machine")


_HOLDER = """
import sys
from pathlib import Path
from animegraph.apps.prepare import fit_guides
from animegraph.baselines.stored import model_path
from db.lock import writer_lock
db = Path(sys.argv[1])
with writer_lock(db, what="database"):
    print("locked", flush=True)
    if sys.stdin.readline().strip() == "fit":
        fit_guides(db)
        for name in sys.argv[2:]:
            path = model_path(db, name)
            print(name, path.stat().st_mtime_ns if path.is_file() else 0, flush=True)
"""


def _hold_lock(db):
    """A process holding ``db``'s writer lock (as the demo's guide fit does) until told
    ``fit`` (it fits the guides, prints their files' times) or anything else."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    child = subprocess.Popen([sys.executable, "-c", _HOLDER, str(db), *GUIDES],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                             env={**os.environ, "PYTHONPATH": str(root)})
    assert child.stdout.readline().strip() == "locked"
    return child


def test_a_synth_meeting_a_guide_fit_under_way_waits_and_takes_its_guides(db_copy, capsys):
    # The demo fits the guides in a process beside it; a synth started meanwhile fitted
    # them again itself (no lock), on the same cores, and overwrote them.
    import threading

    from animegraph.apps.commands.synth_plan import load_guide

    child = _hold_lock(db_copy)
    got = []
    synth = threading.Thread(target=lambda: got.append(
        load_guide(db_copy, AUDIO_ONLY_GUIDE, asked=False)))
    synth.start()
    try:
        while "waiting for another process writing" not in capsys.readouterr().err:
            assert synth.is_alive()
            synth.join(0.1)
    finally:
        out, _ = child.communicate("fit\n", timeout=600)
        synth.join()
    stored = {name: int(ns) for name, ns in (line.split() for line in out.splitlines())}
    assert {name: model_path(db_copy, name).stat().st_mtime_ns if model_path(
        db_copy, name).is_file() else 0 for name in GUIDES} == stored  # none fitted again
    guides = got[0] if isinstance(got[0], tuple) else (got[0],)
    assert len([g for g in guides if g is not None]) == len([n for n in stored if stored[n]])


def test_a_default_guide_not_had_for_a_busy_database_is_not_kept_as_unfit(db_copy, capsys,
                                                                           monkeypatch):
    from animegraph.apps.commands.synth_plan import load_guide
    from animegraph.baselines import base

    monkeypatch.setattr(base, "FIT_WAIT_S", 0.5)
    child = _hold_lock(db_copy)
    try:
        assert load_guide(db_copy, GUIDES[0], asked=False) is None
    finally:
        child.communicate("stop\n", timeout=60)
    err = capsys.readouterr().err
    assert "is being written by another process" in err
    assert unfit_reason(db_copy, GUIDES[0]) is None  # the next run tries again
