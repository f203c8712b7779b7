"""``animegraph info``: what a motion database holds."""

from __future__ import annotations

from collections import Counter

from animegraph.baselines.stored import stored_models
from db.store import Database
from ingest.speech.phones import PHONES


def database_info(db: Database) -> dict:
    """A JSON-able summary of ``db``: manifest, phones, segmentation, components.

    Raises
    ------
    DataError
        If the manifest or a table lacks what the summary reads (one line naming it).
    """
    try:
        info = _database_info(db)
        info_lines(info)  # every field it prints has the type it needs
        return info
    except (KeyError, TypeError, AttributeError, ValueError) as exc:
        raise db.damaged("manifest.json", f"it lacks or mistypes {exc}") from None


def _database_info(db: Database) -> dict:
    m = db.manifest
    animes = db.table("animes", columns=["phoneme"]).column("phoneme").to_pylist()
    clips = db.table("clips", columns=["segmentation", "speaker"]).to_pylist()
    components = [{k: (None if isinstance(v, float) and v != v else v) for k, v in c.items()}
                  for c in db.table("components").to_pylist()]
    phones = Counter(animes)
    return {
        "path": str(db.root), "version": db.version_dir.name,
        "schema_version": m["schema_version"], "animegraph_version": m.get("animegraph_version"),
        "created": m.get("created"), "kind": m["kind"], "n_channels": m["n_channels"],
        "fps": m["fps"], "n_clips": m["n_clips"], "n_animes": m["n_animes"],
        "n_frames": m["n_frames"], "duration_s": m["duration_s"],
        "clips_per_emotion": m["clips_per_emotion"], "corpora": m["corpora"],
        "speakers": sorted({c["speaker"] for c in clips if c["speaker"]}),
        "segmentation": dict(Counter(c["segmentation"] for c in clips)),
        # by count, then name: ties must not follow the order the clips were read in
        "phones": dict(sorted(phones.items(), key=lambda kv: (-kv[1], kv[0]))),
        "phones_missing": [p for p in PHONES if p not in phones],
        "n_pcs": m["n_pcs"], "variance_kept": m["variance_kept"],
        "variance_target": m["variance_target"], "ica_converged": m["ica_converged"],
        "components": components,
        "emotion": m.get("emotion"),
        "baselines": stored_models(db.root),
    }


def _origin(source: str | None) -> str:
    """Why this database: named by an option or a variable (``--db``, ``$ANIMEGRAPH_DB``),
    or the default, said as such ("chosen by the demo's default database" said neither)."""
    if not source:
        return ""
    if source.startswith(("--", "$")):
        return f"; named by {source}"
    return f"; {source}, the default (no --db given, $ANIMEGRAPH_DB not set)"


def info_lines(info: dict) -> list[str]:
    """The summary as lines of text."""
    emotions = ", ".join(f"{e} {n}" for e, n in info["clips_per_emotion"].items())
    rare = sorted(info["phones"].items(), key=lambda kv: (kv[1], kv[0]))[:5]
    lines = [
        f"database:   {info['path']} ({info['version']}, schema {info['schema_version']}, "
        f"written by animegraph {info['animegraph_version']} at {info['created']})"
        + _origin(info.get("chosen_by")),
        f"motion:     {info['kind']}, {info['n_channels']} channels at {info['fps']:g} fps",
        f"clips:      {info['n_clips']} ({emotions}); {info['duration_s'] / 60:.1f} min, "
        f"{info['n_frames']} frames; corpora {', '.join(info['corpora'])}",
        f"speakers:   {', '.join(info['speakers']) or '(not given)'}",
        f"animes:     {info['n_animes']}; {len(info['phones'])} phones present"
        + (f", missing {' '.join(info['phones_missing'])}" if info["phones_missing"] else "")
        + "; rarest " + ", ".join(f"{p} {n}" for p, n in rare),
        "segmented:  " + ", ".join(f"{k} {v}" for k, v in info["segmentation"].items()),
        f"model:      {info['n_pcs']} principal components keep "
        f"{100 * info['variance_kept']:.1f} % of the variance (target "
        f"{100 * info['variance_target']:.0f} %), as many independent components; FastICA "
        + ("converged" if info["ica_converged"] else "did NOT converge"),
    ]
    split = bool(info["components"]) and "label" in info["components"][0]
    if split:
        lines.append("components: #   motion share   low-pass cutoff   label     speech  "
                     "emotion (same-emotion baseline; pair)")
    else:
        lines.append("components: #   motion share   low-pass cutoff")
    for c in info["components"]:
        line = (f"            {c['component']:<3d} {100 * c['motion_share']:6.1f} %"
                f"       {c['cutoff_hz']:6.2f} Hz")
        if split:
            line += (f"      {c['label']:<8s} {_num(c['speech_score'], 3):>6s}  "
                     f"{_num(c['emotion_score'], 2):>6s} ({_num(c['emotion_baseline'], 2)}; "
                     f"{c['emotion_pair'] or '-'})")
        lines.append(line)
    emotion = info.get("emotion")
    if emotion:
        lines.append(f"emotion:    {_ids('emotion', emotion['emotion_components'])}, "
                     f"{_ids('speech', emotion['speech_components'])} (Cao et al. "
                     "§5.1.3: emotion = differs between emotions after DTW alignment; "
                     "speech = its Eq. 9 reconstruction captures mouth motion)")
        lines.append(f"mappings:   {len(emotion['mappings'])} (F_ij, §5.2)"
                     + (": " + ", ".join(emotion["mappings"]) if emotion["mappings"] else ""))
        clf = emotion.get("classifier")
        lines.append("classifier: " + (f"SVM ({clf['kernel']} kernel, {clf['features']} "
                                       f"features, {clf.get('normalize', 'no')} "
                                       f"normalisation) over {', '.join(clf['classes'])}"
                                       if clf else "none"))
        for note in emotion.get("notes", []):
            lines.append(f"note:       {note}")
    lines += _baseline_lines(info.get("baselines", []))
    return lines


def _baseline_lines(models: list[dict]) -> list[str]:
    """One line per stored baseline model (``animegraph fit``, ``synth --method``)."""
    if not models:
        return ["baselines:  none fitted (animegraph fit --db DB --method M)"]
    lines = []
    for k, m in enumerate(models):
        head = "baselines:  " if k == 0 else " " * 12
        if "error" in m:
            lines.append(f"{head}{m['method']} ({m['db_version']}): {m['error']}")
            continue
        params = ", ".join(f"{p}={v}" for p, v in sorted(m["params"].items())
                           if p != "random_state")
        state = ("" if m["current"] else
                 f"; stale, fitted on {m['db_version']} (refitted at next use)")
        lines.append(f"{head}{m['method']} ({params}); {m['n_channels']} channels, "
                     f"{m['bytes'] / 1e6:.1f} MB{state}")
    return lines


def _num(value, digits: int) -> str:
    if value is None or value != value:  # NaN: not measurable on this database
        return "-"
    return f"{value:.{digits}f}"


def _ids(kind: str, ids) -> str:
    """"emotion components 0 2 3", or "no emotion components"."""
    return f"{kind} components " + " ".join(str(i) for i in ids) if ids else \
        f"no {kind} components"
