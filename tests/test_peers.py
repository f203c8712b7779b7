"""Peer rows: openfacefx and pylipsync shape weights mapped linearly to the face."""

from __future__ import annotations

import numpy as np
import pytest

from animegraph.baselines import peers
from animegraph.baselines.peers import PEERS, OpenFaceFX, PyLipSync
from animegraph.motion import measures
from db.errors import DataError
from db.store import Database
from ingest.tables import prepared_from_database


@pytest.fixture(scope="module")
def clips(tiny_db):
    return sorted(prepared_from_database(Database.open(tiny_db[0])), key=lambda c: c.clip_id)


@pytest.mark.parametrize("cls", [OpenFaceFX, PyLipSync])
def test_peer_rows_follow_the_mouth(cls, clips):
    pytest.importorskip(cls.method)
    train, test = clips[:-4], clips[-4:]
    peer = cls().fit(train)
    assert peer.coef_.shape[0] > 2  # a weight per shape, not one signal
    names = list(peer.channels_)
    r_peer = []
    for clip in test:
        truth = clip.motion.astype(np.float64)
        pred = peer.predict(clip.audio, clip.sample_rate, n_frames=len(truth))
        assert pred.shape == truth.shape and np.isfinite(pred).all()
        r_peer.append(measures.motion_scores(pred, truth, names, list(peer.groups_),
                                             peer.kind_, np.arange(len(names)))["mouth_r"])
    # On clean synthetic speech both peers see the mouth (pylipsync's vowel templates
    # least: mouth R 0.20 on these four clips).
    assert np.mean(r_peer) > 0.1


def test_a_missing_peer_is_one_line(monkeypatch, clips):
    import builtins

    real = builtins.__import__

    def no_pylipsync(name, *args, **kwargs):
        if name.startswith("pylipsync"):
            raise ImportError("No module named 'pylipsync'")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(peers, "_REMEMBERED", {})  # weights of earlier tests' clips
    monkeypatch.setattr(builtins, "__import__", no_pylipsync)
    with pytest.raises(DataError, match=r"pylipsync peer is not installed.*\[peers\]"):
        PyLipSync().fit(clips[:3])
    assert set(PEERS) == {"openfacefx", "pylipsync"}
