"""Which path ``animegraph synth`` takes: where its phones come from, k-best or the
paper's search, the guiding baseline (loaded, or fitted on first use), and the
path line that says so."""

from __future__ import annotations

import argparse
import sys

from animegraph.apps.commands.common import UsageError
from db.errors import AnimeGraphError, BusyError


def _synth_given(args: argparse.Namespace) -> tuple[str, bool, bool]:
    """What ``synth``'s phones come from (for the path line), whether they are known (labels
    or a transcript), and whether the paper's search was asked for."""
    engine = args.phones_engine or "auto"
    if args.labels is not None:
        given = "phone labels given"
    elif args.text is not None:
        given = f"transcript given (aligned by the {engine} phone engine)"
    else:
        how = ("named by hama, placed by PocketSphinx" if engine == "auto"
               else f"recognised by the {engine} phone engine")
        given = f"audio only (phones {how})"
    searched = (args.exact or args.window is not None or args.search is not None
                or args.helper is not None)
    return given, args.labels is not None or args.text is not None, searched


def synth_path(args: argparse.Namespace) -> tuple[int | None, str]:
    """The k-best setting ``synth`` uses, and a line saying which path runs and why."""
    from animegraph.synthesis.path import synthesis_path  # shared with batch

    given, known, searched = _synth_given(args)
    return synthesis_path(given, known_phones=known, k_best=args.k_best, searched=searched,
                          context=args.context_ranking)


def synth_plan(args: argparse.Namespace, path: str) -> tuple[str, str | None, float, bool]:
    """The path line completed with the audio cost, candidates and guide, and the guide
    (:func:`_synth_guide`)."""
    from animegraph.synthesis.path import guide_line

    if (args.audio_cost or "plp") != "plp":
        path += f"; audio cost {args.audio_cost} (beyond the paper)"
    if args.candidates == "likely":
        path += "; candidates from the likely phones (beyond the paper)"
    guide_name, guide_blend, guide_rank = _synth_guide(args)
    path += guide_line(guide_name, guide_blend, guide_rank, known_phones=args.labels is not
                       None or args.text is not None, asked=args.guide is not None)
    return path, guide_name, guide_blend, guide_rank


def _synth_guide(args: argparse.Namespace) -> tuple[str | None, float, bool]:
    """``synth --guide``, ``--guide-blend`` and ``--guide-rank``: the guiding baseline
    (None: off; by default the audio-only path's,
    :func:`animegraph.synthesis.path.audio_only_guide`), its share of the output motion,
    and whether it ranks the animes too."""
    from animegraph.synthesis.guide import GUIDE_BLEND
    from animegraph.synthesis.path import audio_only_guide

    share = GUIDE_BLEND if args.guide_blend is None else float(args.guide_blend)
    if not 0.0 <= share <= 1.0:
        raise UsageError(f"animegraph synth: --guide-blend must be in [0, 1], got {share:g}")
    _, known, searched = _synth_given(args)
    name = (audio_only_guide(known_phones=known, searched=searched) if args.guide is None
            else None if args.guide == "none" else args.guide)
    if name is None and (args.guide_blend is not None or args.guide_rank):
        flag = "--guide-rank" if args.guide_rank else "--guide-blend"
        raise UsageError(f"animegraph synth: {flag} needs a guide (e.g. --guide mu-mlp; "
                         f"the default one is for audio only without a search option)")
    if name is not None and share == 0 and not args.guide_rank:
        raise UsageError("animegraph synth: --guide-blend 0 leaves the guide nothing to do: "
                         "add --guide-rank, or --guide none")
    return name, share, args.guide_rank


def load_guide(db, name: str | None, *, asked: bool = True):
    """The guiding baseline stored with the database ``db`` (mu-mlp and ppg-ridge restored
    without scikit-learn), fitted and stored on first use (saying so on stderr), or None;
    for a mean of several (``mu-mlp+ppg-ridge``), the tuple of those that could be had.

    A default guide (not ``asked``) that cannot be fitted or stored is left out with a
    warning line, and why is kept with the database (the path line says it again,
    :func:`guide_shortfall`): the path falls back to the other guides, or k-best alone."""
    if name is None:
        return None
    if "+" in name:
        parts = [load_guide(db, part, asked=asked) for part in name.split("+")]
        parts = [p for p in parts if p is not None]
        return None if not parts else parts[0] if len(parts) == 1 else tuple(parts)
    from animegraph.baselines.stored import load_forward, model_path, record_unfit, unfit_reason

    model = load_forward(db, name)
    if model is not None:
        return model
    reason = None if asked else unfit_reason(db, name)
    if reason is not None:  # a default guide already failed on this version: not again
        print(f"animegraph: warning: no {name} guide ({reason}; kept from an earlier run, "
              f"--guide {name} to try again)", file=sys.stderr)
        return None
    from animegraph.baselines.base import fitted_model, load_model

    if not model_path(db, name).is_file() or load_model(db, name) is None:
        from animegraph.apps.prepare import fit_estimate

        how_long = fit_estimate(db, name)  # said once: stored, it is not fitted again
        print(f"animegraph: fitting {name} on {db} to guide the motion (first use"
              f"{', ' + how_long if how_long else ''}; stored with the database; "
              "'animegraph warmup' or ingest does it ahead) ...", file=sys.stderr)

    def waiting(holder: str) -> None:
        print(f"animegraph: waiting for another process writing {db}{holder} (the demo "
              f"fitting its guides, say): a {name} it stores is taken, not fitted twice ...",
              file=sys.stderr)

    if asked:
        return fitted_model(db, name, on_wait=waiting)
    try:
        return fitted_model(db, name, on_wait=waiting)
    except BusyError as exc:  # not a reason to keep: the next run tries again
        print(f"animegraph: warning: no {name} guide ({exc})", file=sys.stderr)
        return None
    except (AnimeGraphError, OSError) as exc:
        print(f"animegraph: warning: no {name} guide ({exc})", file=sys.stderr)
        record_unfit(db, name, str(exc))
        return None


def guide_shortfall(db, name: str | None, got: tuple[str, ...]) -> str:
    """What the path line adds when parts of the guide ``name`` could not be had on the
    database ``db``, with why (as :func:`load_guide` kept it)."""
    from animegraph.baselines.stored import unfit_reason

    missing = [part for part in (name or "").split("+") if part and part not in got]
    if not missing:
        return ""
    why = [unfit_reason(db, part) or "said above" for part in missing]
    if len(missing) > 1:
        why = [f"{part}: {reason}" for part, reason in zip(missing, why, strict=True)]
    return (f"; but without its {' and '.join(missing)} guide, which could not be fitted "
            f"({'; '.join(why)})")


def recognized_guide(args: argparse.Namespace):
    """With ``--text`` and no guide: what loads the speech-alone path's guide, for
    ``synthesize`` to call if the transcript cannot be aligned after all (the check
    before it passed, PocketSphinx found no path); else None."""
    from animegraph.synthesis.path import audio_only_guide

    if args.text is None or args.guide is not None:
        return None
    name = audio_only_guide(known_phones=False, searched=_synth_given(args)[2])
    if name is None:
        return None
    return lambda: load_guide(args.db, name, asked=False)
