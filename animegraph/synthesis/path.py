"""Which synthesis runs: the paper's search, or k-best blending, by what the input has.

Speech with a transcript (phones force-aligned) or with phone labels is synthesized by
default with k-best blending (beyond the paper: :func:`animegraph.synthesis.render_k_best`,
each phone the rank-weighted mean of its ``TRANSCRIPT_K_BEST`` best-matching animes around
the exact search's sequence). The paper's synthesis (one recorded anime a phone, Cao et
al. 2005 §4.2-4.3) is one flag away (``--exact``, ``--window K`` or ``--search``; a
script line's ``exact``/``window``). Speech alone (phones recognised) is k-best blended
too, over ``AUDIO_ONLY_K_BEST`` animes: recognised phones are often wrong, and the paper's
single-anime search trusts them (FACEGOOD, talkingface, GRID: docs/results/lipsync.md); and, beyond
that, averaged 50/50 with the motion two
statistical models (mu-mlp
and ppg-ridge, :data:`AUDIO_ONLY_GUIDE`) predict for the speech
(:mod:`animegraph.synthesis.guide`; ``synth --guide``). ``synth`` and ``batch`` both decide here.

Why: on the one real database with transcripts (GRID s1, 640 clips of one speaker, 159
held out: docs/results/lipsync.md, "GRID s1") k-best 20 was ahead of the paper's exact and
windowed search and of every statistical baseline on mouth R and lip vertex error, with
phones aligned from the transcript. Averaging the k best-matching samples instead of
taking the single best one is k-nearest-neighbour regression rather than 1-nearest-
neighbour: a lower-variance estimate of the motion for the phone (Hastie, Tibshirani &
Friedman, The Elements of Statistical Learning, §2.3.2). On the synthetic corpus, where
the motion is generated from the very phones given, the exact search keeps a higher
mouth R (the search's runs of consecutive animes carry the generator's coarticulation
exactly): it is reported, not decisive, because its motion is not recorded motion.

With known phones the k best animes are ranked by phonetic context first
(:data:`KNOWN_PHONES_CONTEXT`; :func:`animegraph.search.k_best` with ``context``: the
animes recorded between the same neighbour phones, or visemes, before the audio cost;
unit selection's context target cost, Hunt & Black 1996). Set a priori, then measured
(docs/results/lipsync.md, "GRID s1" and "Synthetic corpus"): on GRID s1 with aligned phones
mouth R
0.884 -> 0.891 (paired +0.007 [+0.003, +0.010]), lip RMSE lower; on the synthetic corpus
mouth R 0.827 -> 0.873 (+0.046, better on every clip), ahead of the exact search's errors.
With recognised phones it is not the default (#13's path): on GRID it helped hama's
phones and hurt PocketSphinx's.
"""

from __future__ import annotations

#: k-best blending's K when the phones are known (a transcript or labels).
TRANSCRIPT_K_BEST = 20
#: ... and when they are recognised from the audio alone.
AUDIO_ONLY_K_BEST = 20
#: With known phones, k-best ranks each phone's animes by phonetic context first (their
#: recorded neighbour phones against the input's; :func:`animegraph.search.k_best` with
#: ``context``, beyond the paper: unit selection's context target cost, Hunt & Black 1996).
KNOWN_PHONES_CONTEXT = True
#: What the path line says of it.
CONTEXT_PHRASE = ", ranked by phonetic context first"

#: The baseline(s) whose predicted motion the audio-only path averages with the animes'
#: (:mod:`animegraph.synthesis.guide`, share ``GUIDE_BLEND``); None: the animes alone.
#: The mean of mu-mlp (Hong et al. 2002: MFCCs, so it hears the speaker as well as the
#: phone) and ppg-ridge (:mod:`animegraph.baselines.ppg_ridge`: a recogniser's phone
#: posteriors, speaker-independent): each alone guided better than the other on some data
#: (mu-mlp within a speaker, ppg-ridge across speakers), and their mean beat both on
#: FACEGOOD, talkingface within speaker and GRID, and mu-mlp alone across talkingface's
#: speakers (docs/results/lipsync.md, "FACEGOOD", "talkingface" and "GRID s1"); forecast
#: combination with equal weights (Bates & Granger 1969), as the blend with the animes
#: is. mu-mlp alone was the guide before it.
AUDIO_ONLY_GUIDE: str | None = "mu-mlp+ppg-ridge"


def audio_only_guide(*, known_phones: bool, searched: bool = False) -> str | None:
    """The guide of synthesis by default: :data:`AUDIO_ONLY_GUIDE` for speech alone
    without a search asked for, else none (the known-phones path is unguided)."""
    return None if known_phones or searched else AUDIO_ONLY_GUIDE


def guide_line(name: str | None, share: float, rank: bool, *, known_phones: bool,
               asked: bool) -> str:
    """What the path line adds for a guide (empty without one): the default audio-only
    guide with why, or the guide as asked. A claim it makes is one the results
    measured: the default blend, not the ranking (``--guide-rank``), which helped within
    one speaker and hurt across speakers (docs/results/lipsync.md,
    "Options measured against the default")."""
    if name is None:
        return ""
    parts = name.split("+")
    motion = (f"{name}'s predicted motion" if len(parts) == 1 else
              "the mean of " + " and ".join(f"{p}'s" for p in parts) + " predicted motion")
    ranked = (f"; each phone's animes also ranked by their distance to {motion} (as asked: "
              "it helped within one speaker, not across speakers)" if rank else "")
    if share == 0:
        blend = ""
    elif share == 0.5:
        blend = f"; the output the mean of that and {motion}"
    elif share == 1:
        blend = f"; the output {motion} alone (none of the animes')"
    else:
        blend = f"; the output {share:g} {motion}, {1 - share:g} the animes' motion"
    if not asked and not known_phones:
        why = (" (the blend measured best on real speech without a transcript, FACEGOOD, "
               "talkingface and GRID; --guide none for the animes alone)" if blend else "")
        return f"{blend}{why}{ranked}"
    return f"{blend}{ranked} (beyond the paper)"


def synthesis_path(given: str, *, known_phones: bool, k_best: int | None = None,
                   searched: bool = False, context: bool | None = None) -> tuple[int | None, str]:
    """The k-best setting for speech, and a line saying which path runs and why.

    Parameters
    ----------
    given : str
        What the phones come from, for the line (e.g. ``"transcript given"``).
    known_phones : bool
        The phones are known (a transcript or labels), not recognised from the audio.
    k_best : int, optional
        K asked for explicitly (``--k-best``): used as it is.
    searched : bool
        A search was asked for (``--exact``, ``--window``, ``--search``, a script line's
        ``exact`` or ``window``): the paper's synthesis, one anime a phone.
    context : bool, optional
        Context ranking asked for (``--context-ranking`` / ``--no-context-ranking``); None:
        :data:`KNOWN_PHONES_CONTEXT` with known phones, off without. Only for the line.

    Returns
    -------
    (int or None, str)
        K for :func:`animegraph.synthesis.synthesize` (None: the paper's synthesis), and
        the path line (``animegraph: path: ...``).
    """
    if k_best is not None:
        return k_best, f"{given}; k-best {k_best} as asked"
    if searched:
        return None, f"{given}: the paper's search (one anime a phone, §4) as asked"
    k, where = ((TRANSCRIPT_K_BEST, "with a transcript, GRID") if known_phones
                else (AUDIO_ONLY_K_BEST, "without a transcript"))
    ranked = (CONTEXT_PHRASE
              if (KNOWN_PHONES_CONTEXT and known_phones if context is None else context)
              else "")
    return k, (f"{given}: each phone the mean of its {k} best animes{ranked} (k-best measured "
               f"best on real speech {where}; --exact for the paper's search)")


def known_phones_path(given: str, *, k_best: int | None = None,
                      searched: bool = False) -> tuple[int | None, str]:
    """:func:`synthesis_path` for speech whose phones are known (``batch``'s lines)."""
    return synthesis_path(given, known_phones=True, k_best=k_best, searched=searched)
