"""The shortlist of k-best's candidates: the full ranking's first N, its bound, its options."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from test_search import EMOTIONS, random_graph

from animegraph import search as S
from animegraph.apps.cli import main
from animegraph.search import SearchWeights, candidates, search
from animegraph.search.dtw import audio_costs_many
from animegraph.search.problem import Problem, context_match
from animegraph.search.shortlist import box_bounds, shortlist
from db.errors import ParameterError

PHONES = ("AA", "B", "M", "T", "S", "IY")


def with_prosody(rng: np.random.Generator, g):
    """``g`` with random prosody curves of 1 to 9 frames, a third of them copies of an
    earlier one and the values on a coarse grid (ties in the audio cost, as replicated
    databases have), one-frame curves among them (the bound is then tight)."""
    curves = []
    for _ in range(g.n_nodes):
        if curves and rng.random() < 0.33:
            curves.append(curves[int(rng.integers(len(curves)))])
        else:
            curves.append(np.round(rng.normal(size=(int(rng.integers(1, 10)), 9)) * 4) / 4)
    offsets = np.concatenate([[0], np.cumsum([len(c) for c in curves])]).astype(np.int64)
    return replace(g, prosody_offsets=offsets,
                   prosody_values=np.concatenate(curves).astype(np.float32))


def full_ranking_first(g, cands, audio, size, *, emotion, context, weights):
    """Per input, the first ``size`` candidates by k_best's order (as k_best sorts them)."""
    problem = Problem.build(g, cands, audio, weights, emotion)
    match = context_match(g, cands, problem.cn, problem.off)
    out = []
    for i in range(len(cands)):
        lo, hi = problem.off[i], problem.off[i + 1]
        if context:
            order = np.lexsort((problem.u[lo:hi], -match[lo:hi], problem.mismatch[lo:hi]))
        else:
            order = np.argsort(problem.u[lo:hi], kind="stable")
        out.append(np.sort(cands.nodes[i][order[:size]]))
    return out


def random_case(seed: int):
    rng = np.random.default_rng(seed)
    g = with_prosody(rng, random_graph(rng, int(rng.integers(15, 40)), PHONES))
    phones = [str(p) for p in rng.choice(PHONES, size=int(rng.integers(1, 6)))]
    curves = [np.round(rng.normal(size=(int(rng.integers(1, 8)), 9)) * 4) / 4
              for _ in phones]
    emotion = [None, *EMOTIONS][int(rng.integers(4))]
    cands = candidates(g, phones, emotion=emotion)
    audio = audio_costs_many(curves, g.prosody_values, g.prosody_offsets, cands.nodes)
    weights = SearchWeights(w_audio=float(rng.choice([0.01, 1.0, 300.0])))
    return rng, g, cands, curves, audio, emotion, weights


@pytest.mark.parametrize("seed", range(60))
def test_shortlist_is_the_full_rankings_first_n(seed):
    rng, g, cands, curves, audio, emotion, weights = random_case(seed)
    context = bool(rng.integers(2))
    size = int(rng.integers(1, max(cands.sizes) + 3))
    want = full_ranking_first(g, cands, audio, size, emotion=emotion, context=context,
                              weights=weights)
    for given in ({"curves": curves}, {"costs": audio}):
        got = shortlist(g, cands, size, weights=weights, emotion=emotion, context=context,
                        **given)
        assert got.n_all == sum(cands.sizes)
        for i in range(len(cands)):
            np.testing.assert_array_equal(got.cands.nodes[i], want[i])
            # The costs of the kept candidates are the full computation's, to the bit.
            place = np.searchsorted(cands.nodes[i], want[i])
            np.testing.assert_array_equal(got.audio[i], audio[i][place])
        assert got.cands.phones == cands.phones and got.cands.backoff == cands.backoff


@pytest.mark.parametrize("seed", range(20))
def test_box_bound_never_exceeds_the_audio_cost(seed):
    rng, g, cands, curves, audio, *_ = random_case(seed)
    for band in (None, 1):
        exact = audio_costs_many(curves, g.prosody_values, g.prosody_offsets, cands.nodes,
                                 band=band)
        for lb, cost in zip(box_bounds(g, curves, cands.nodes), exact, strict=True):
            assert np.all(lb >= 0) and np.all(lb <= cost)


def test_the_bound_spares_audio_costs_on_separated_curves():
    # Inputs near half the animes' curves and far from the others': the far ones' bounds
    # exceed the near ones' costs, so their DTW is never run.
    rng = np.random.default_rng(0)
    g = random_graph(rng, 30, ("AA",))
    curves = [np.full((4, 9), 10.0 * (a % 2)) + rng.normal(size=(4, 9)) * 0.1
              for a in range(g.n_nodes)]
    g = replace(g, prosody_offsets=np.arange(g.n_nodes + 1, dtype=np.int64) * 4,
                prosody_values=np.concatenate(curves).astype(np.float32))
    cands = candidates(g, ["AA"])
    got = shortlist(g, cands, 3, curves=[np.zeros((5, 9))])
    assert got.n_costs < got.n_all // 2 + 3
    assert np.all(got.cands.nodes[0] % 2 == 0)


@pytest.mark.parametrize("seed", range(20))
def test_k_best_over_the_shortlist_ranks_as_over_every_candidate(seed):
    rng, g, cands, curves, audio, emotion, weights = random_case(seed)
    context = bool(rng.integers(2))
    k = int(rng.integers(1, 5))
    size = k + int(rng.integers(0, 3))
    cut = shortlist(g, cands, size, curves=curves, weights=weights, emotion=emotion,
                    context=context)
    picked = search(g, cut.cands, cut.audio, weights=weights, emotion=emotion).nodes
    over_cut = S.k_best(g, cut.cands, cut.audio, picked, k, weights=weights, emotion=emotion,
                        context=context)
    over_all = S.k_best(g, cands, audio, picked, k, weights=weights, emotion=emotion,
                        context=context)
    for a, b in zip(over_cut, over_all, strict=True):
        np.testing.assert_array_equal(a, b)


def test_shortlist_rejects_bad_arguments():
    _, g, cands, curves, audio, *_ = random_case(0)
    for size in (0, -1, True, 2.5, "3"):
        with pytest.raises(ParameterError, match="shortlist size"):
            shortlist(g, cands, size, curves=curves)
    with pytest.raises(ParameterError, match="exactly one of"):
        shortlist(g, cands, 2)
    with pytest.raises(ParameterError, match="exactly one of"):
        shortlist(g, cands, 2, curves=curves, costs=audio)
    with pytest.raises(ParameterError, match="one curve or cost array per input"):
        shortlist(g, cands, 2, curves=curves[:-1] if len(curves) > 1 else curves * 2)
    with pytest.raises(ParameterError, match=r"costs\[0\] must have shape"):
        shortlist(g, cands, 2, costs=[np.zeros(len(c) + 1) for c in cands.nodes])


@pytest.mark.parametrize("value, needle", [
    ("0", "whole number >= 1 or 'all'"), ("-2", "whole number >= 1 or 'all'"),
    ("some", "whole number >= 1 or 'all'"), ("1.5", "whole number >= 1 or 'all'"),
])
def test_cli_shortlist_bad_values_are_one_line_and_exit_2(capsys, tmp_path, value, needle):
    code = main(["synth", str(tmp_path / "x.wav"), "--db", str(tmp_path / "db"), "-o",
                 str(tmp_path / "y.csv"), "--shortlist", value])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1 and needle in err[0] and "Traceback" not in err[0]


def test_cli_shortlist_needs_k_best(capsys, tmp_path):
    code = main(["synth", str(tmp_path / "x.wav"), "--db", str(tmp_path / "db"), "-o",
                 str(tmp_path / "y.csv"), "--exact", "--shortlist", "5"])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1 and "--shortlist" in err[0]
