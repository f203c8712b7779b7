"""Evaluate the phone engines (ingest.speech) against real and synthetic phone timing.

Both engines (``--engines hama pocketsphinx``), side by side, on up to three data sets:

* ``synthetic`` -- a synthetic corpus (eSpeak NG speech whose phones and their timing are
  exact, five emotions): forced alignment of the transcript (onset errors of the phones
  matched to the reference by an edit-distance alignment, phone error rate) and phone
  recognition without transcript (phone error rate, onset errors of the phones it got).
* ``emodb`` -- Berlin EmoDB (``../shared/data/emodb``; German, real, emotional), phone
  labels from its ``lablaut`` files: recognition only (the engines' aligners pronounce
  English). SAMPA is mapped to ARPAbet by :data:`SAMPA_TO_ARPABET` (nearest English phone;
  a stop's closure ``_t``/``t`` and release ``!t``/``tasp`` are one phone; marker-only
  labels ``+hoe``, ``-sth`` ... are annotations, not segments; each label starts at its
  time (xlabel), the final ``.`` marks the end of speech; the glottal stop ``?`` and
  breath ``(`` are ``SIL``). This copy is cut (or zero-padded) to 2.0 s: labels
  past 2.0 s are dropped and the last one is cut there.
* ``grid`` -- GRID speaker s1 (``../shared/data/grid/s1``; English, real), the corpus' own
  word alignments (``*.align``): forced alignment of the transcript gives word onset and
  offset errors (a word's phones found by an edit-distance alignment of the engine's
  phones to the transcript's CMUdict pronunciation); recognition gives the phone error
  rate against the transcript's CMUdict pronunciation (no word recogniser: no WER).

Speed is seconds of computation per second of audio (warm: each engine is loaded first).

    python scripts/eval_segmentation.py --data synthetic emodb grid --limit 100 --json seg.json
    python scripts/eval_segmentation.py --corpus /path/to/corpus --data synthetic
"""

from __future__ import annotations

import argparse
import json
import logging
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ingest.corpus.synthetic import CorpusConfig, generate_corpus
from ingest.formats.phones_csv import Segment, read_phones_csv
from ingest.formats.wav import read_wav
from ingest.speech import ctc
from ingest.speech import sphinx as ps
from ingest.speech.engines import aligner, recognizer
from ingest.speech.g2p import pronounce
from ingest.speech.phones import SILENCE
from ingest.speech.scoring import boundary_errors, edit_alignment, matched_onsets, phone_error_rate
from ingest.speech.tiling import snap_labels

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
#: EmoDB's copy is cut to this many seconds.
EMODB_SECONDS = 2.0
#: GRID's .align times are in units of 1/25000 s.
GRID_UNIT = 25000.0

#: German SAMPA (EmoDB's lablaut) -> ARPAbet: the nearest English phone; vowel + vocalic r
#: (``i6``) and rare diphthongs keep their vowel; front rounded vowels as the engines map
#: IPA (``ingest.speech.ctc.IPA_TO_ARPABET``): y -> UW, Y -> UH, 2 9 -> ER.
SAMPA_TO_ARPABET: dict[str, str] = {
    "a": "AA", "a:": "AA", "A": "AA", "e": "EY", "e:": "EY", "E": "EH", "E:": "EH",
    "i": "IY", "i:": "IY", "I": "IH", "o": "OW", "o:": "OW", "O": "AO", "u": "UW",
    "u:": "UW", "U": "UH", "y": "UW", "y:": "UW", "Y": "UH", "2": "ER", "2:": "ER",
    "9": "ER", "8": "ER", "@": "AH", "6": "AH", "aI": "AY", "aU": "AW", "AU": "AW",
    "aO": "AW", "AO": "AW", "ao": "AW", "OY": "OY", "OU": "OW", "i6": "IY", "a6": "AA",
    "E6": "EH", "@6": "AH", "I6": "IH", "Y6": "UH", "ia": "IY", "i@": "IY", "e@": "EY",
    "I@": "IH", "@E": "AH", "@a": "AH", "@O": "AH",
    "p": "P", "b": "B", "t": "T", "d": "D", "k": "K", "g": "G", "f": "F", "v": "V",
    "s": "S", "z": "Z", "S": "SH", "Z": "ZH", "C": "HH", "x": "HH", "X": "HH", "h": "HH",
    "H": "HH", "j": "Y", "m": "M", "n": "N", "N": "NG", "l": "L", "L": "L", "r": "R",
    "R": "R", "4": "R", "B": "V", "V": "V", "D": "DH", "G": "G", "J": "N", "nn": "N",
    "NN": "NG", "mm": "M", "vv": "V", "ss": "S",
    "pasp": "P", "tasp": "T", "kasp": "K", "basp": "B", "dasp": "D", "gasp": "G",
    "dsap": "D", "gas": "G",
    "?": SILENCE, ".": SILENCE, "(": SILENCE, "(gef": SILENCE,
}


# ---------------------------------------------------------------------------------------------
# Engines
# ---------------------------------------------------------------------------------------------


def _engines(names: list[str]) -> dict[str, dict[str, Callable]]:
    table = {
        "hama": {"align": ctc.align, "recognize": ctc.recognize},
        "pocketsphinx": {"align": ps.align, "recognize": ps.recognize},
        "auto": {"align": aligner("auto"), "recognize": recognizer("auto")},
    }
    return {name: table[name] for name in names}


def _warm(engines) -> None:
    audio = np.random.default_rng(0).normal(0, 0.1, 16000).astype(np.float32)
    for funcs in engines.values():
        funcs["recognize"](audio, 16000)
        try:
            funcs["align"](audio, 16000, "hello")
        except Exception:  # noqa: BLE001 - only warming up
            pass


def _timed(func, *args):
    start = time.perf_counter()
    out = func(*args)
    return out, time.perf_counter() - start


# ---------------------------------------------------------------------------------------------
# Data sets
# ---------------------------------------------------------------------------------------------


def read_lablaut(path: Path, duration: float) -> list[Segment]:
    """EmoDB ``.lablaut`` (xlabel: time, colour, SAMPA label) -> ARPAbet segments.

    Each label *starts* at its time and runs to the next label's (the first label comes
    after leading silence; the last, ``.``, marks the end of speech). Marker-only lines
    (``+hoe``, ``-sth`` ...) annotate the segment they fall in. Stop closure and release
    are one phone. Labels are cut at ``duration``.
    """
    rows: list[tuple[float, str]] = []
    body = False
    for line in path.read_text(encoding="latin-1").splitlines():
        if line.strip() == "#":
            body = True
            continue
        fields = line.split()
        if not body or len(fields) < 3 or fields[2][0] in "+-":
            continue
        rows.append((float(fields[0]), fields[2]))
    pieces: list[list] = []  # [phone, start, end]
    for k, (start, label) in enumerate(rows):
        end = rows[k + 1][0] if k + 1 < len(rows) else duration
        if end <= start:
            continue
        core, release = label.split("+")[0].split(",")[0], False
        if core.startswith("_"):
            core = core[1:]
        elif core.startswith("!"):
            core, release = core[1:], True
        elif core.endswith("asp") or core in ("dsap", "gas"):
            release = True
        if core not in SAMPA_TO_ARPABET:
            core = core.split("-")[0]
        phone = SAMPA_TO_ARPABET.get(core, SILENCE)
        if pieces and pieces[-1][0] == phone and (release or phone == SILENCE):
            pieces[-1][2] = end
        else:
            pieces.append([phone, start, end])
    segments = [Segment(p, s, min(e, duration)) for p, s, e in pieces if s < duration]
    return snap_labels(segments, duration) if segments else [Segment(SILENCE, 0, duration)]


def _mp4_audio(path: Path) -> np.ndarray:
    import imageio_ffmpeg

    out = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-v", "quiet", "-i", str(path), "-f", "s16le",
         "-ac", "1", "-ar", "16000", "-"], capture_output=True, check=True).stdout
    return np.frombuffer(out, "<i2").astype(np.float32) / 32768.0


def _read_align(path: Path) -> list[tuple[str, float, float]]:
    words = []
    for line in path.read_text().splitlines():
        fields = line.split()
        if len(fields) == 3 and fields[2] != "sil":
            words.append((fields[2], int(fields[0]) / GRID_UNIT, int(fields[1]) / GRID_UNIT))
    return words


def word_times(words: list[str], segments: list[Segment]) -> list[tuple[float, float] | None]:
    """Onset and offset of each word in ``segments``, by aligning their phones to the
    words' CMUdict pronunciations (None: no phone of the word was found)."""
    expected: list[str] = []
    owner: list[int] = []
    for k, word in enumerate(words):
        phones = pronounce(word)
        expected += phones
        owner += [k] * len(phones)
    hyp = [s for s in segments if s.phone != SILENCE]
    spans: list[list[float]] = [[] for _ in words]
    for i, j in edit_alignment(expected, [s.phone for s in hyp]):
        if i is not None and j is not None:
            spans[owner[i]] += [hyp[j].start, hyp[j].end]
    return [(min(s), max(s)) if s else None for s in spans]


def _synthetic(folder: Path, engines, limit: int | None) -> list[dict]:
    rows = []
    for clip in sorted((folder / "clips").glob("*.json"))[:limit]:
        meta = json.loads(clip.read_text())
        stem = clip.name[: -len(".json")]
        audio, rate = read_wav(clip.with_name(stem + ".wav"))
        reference = read_phones_csv(clip.with_name(stem + ".phones.csv"))
        for name, funcs in engines.items():
            row = {"data": "synthetic", "engine": name, "clip": stem,
                   "seconds": len(audio) / rate}
            aligned, row["align_time"] = _timed(funcs["align"], audio, rate, meta["text"])
            row["align_errors"] = boundary_errors(reference, aligned).tolist()
            row["align_signed"] = boundary_errors(reference, aligned, signed=True).tolist()
            row["align_per"] = phone_error_rate(reference, aligned)
            rec, row["recognize_time"] = _timed(funcs["recognize"], audio, rate)
            index, signed = matched_onsets(reference, rec)
            row["recognize_errors"] = np.abs(signed).tolist()
            row["recognize_matched"] = index.tolist()
            row["recognize_per"] = phone_error_rate(reference, rec)
            rows.append(row)
    return rows


def _emodb(folder: Path, engines, limit: int | None) -> list[dict]:
    rows = []
    for wav in sorted((folder / "wav").glob("*.wav"))[:limit]:
        labels = folder / "lablaut" / (wav.stem + "xx.lablaut")
        if not labels.exists():
            continue
        audio, rate = read_wav(wav)
        reference = read_lablaut(labels, len(audio) / rate)
        if all(s.phone == SILENCE for s in reference):
            continue
        for name, funcs in engines.items():
            row = {"data": "emodb", "engine": name, "clip": wav.stem,
                   "seconds": len(audio) / rate}
            rec, row["recognize_time"] = _timed(funcs["recognize"], audio, rate)
            index, signed = matched_onsets(reference, rec)
            row["recognize_errors"] = np.abs(signed).tolist()
            row["recognize_signed"] = signed.tolist()
            row["recognize_matched"] = index.tolist()
            row["recognize_per"] = phone_error_rate(reference, rec)
            rows.append(row)
    return rows


def _grid(folder: Path, engines, limit: int | None) -> list[dict]:
    rows = []
    for align_file in sorted(folder.glob("*.align"))[:limit]:
        video = align_file.with_suffix(".mp4")
        if not video.exists():
            continue
        audio = _mp4_audio(video)
        ref_words = _read_align(align_file)
        words = [w for w, _, _ in ref_words]
        text = " ".join(words)
        reference = [Segment(p, 0.0, 1.0) for w in words for p in pronounce(w)]
        for name, funcs in engines.items():
            row = {"data": "grid", "engine": name, "clip": align_file.stem,
                   "seconds": len(audio) / 16000}
            aligned, row["align_time"] = _timed(funcs["align"], audio, 16000, text)
            found = word_times(words, aligned)
            row["onset_errors"] = [abs(f[0] - r[1]) for f, r in zip(found, ref_words,
                                                                   strict=True) if f]
            row["offset_errors"] = [abs(f[1] - r[2]) for f, r in zip(found, ref_words,
                                                                    strict=True) if f]
            row["onset_signed"] = [f[0] - r[1] for f, r in zip(found, ref_words,
                                                               strict=True) if f]
            row["words"], row["words_found"] = len(words), sum(f is not None for f in found)
            row["align_per"] = phone_error_rate(reference, aligned)
            rec, row["recognize_time"] = _timed(funcs["recognize"], audio, 16000)
            row["recognize_per"] = phone_error_rate(reference, rec)
            rows.append(row)
    return rows


# ---------------------------------------------------------------------------------------------
# Summary
# ---------------------------------------------------------------------------------------------


def _ms(rows: list[dict], key: str) -> np.ndarray:
    values = [np.asarray(r[key]) for r in rows if key in r]
    return np.concatenate(values) * 1000 if values else np.zeros(0)


def _stat(values: np.ndarray, q: float) -> float:
    return float(np.percentile(values, q)) if values.size else float("nan")


def summarize(rows: list[dict]) -> dict:
    seconds = sum(r["seconds"] for r in rows)
    out: dict[str, float] = {"clips": len(rows), "audio_s": round(seconds, 1)}
    for key in ("align_errors", "recognize_errors", "onset_errors", "offset_errors"):
        values = _ms(rows, key)
        if values.size:
            out[key.replace("_errors", "_median_ms")] = _stat(values, 50)
            out[key.replace("_errors", "_p90_ms")] = _stat(values, 90)
            out[key.replace("_errors", "_n")] = int(values.size)
    for key in ("align_signed", "recognize_signed", "onset_signed"):
        values = _ms(rows, key)
        if values.size:
            out[key.replace("_signed", "_bias_ms")] = _stat(values, 50)
    for key in ("align_per", "recognize_per"):
        if any(key in r for r in rows):
            out[key] = float(np.mean([r[key] for r in rows if key in r]))
    for key in ("align_time", "recognize_time"):
        if any(key in r for r in rows):
            out[key.replace("_time", "_s_per_s")] = sum(r[key] for r in rows if key in r) / seconds
    if any("words" in r for r in rows):
        out["words_found"] = sum(r["words_found"] for r in rows) / sum(r["words"] for r in rows)
    return out


def common_onsets(rows: list[dict], engines: list[str]) -> dict[str, dict]:
    """Recognised onset errors of each engine over the reference phones that **every**
    engine matched (per clip): the engines then answer for the same boundaries, where
    each one's own median is over the phones it happened to find (a better recogniser
    finds more, and harder, ones).

    Returns
    -------
    dict
        ``{engine: {"recognize_common_median_ms", "recognize_common_p90_ms",
        "recognize_common_n"}}``; empty unless every engine has matched-phone rows.
    """
    by_clip: dict[str, dict[str, dict]] = {}
    for r in rows:
        if "recognize_matched" in r:
            by_clip.setdefault(r["clip"], {})[r["engine"]] = r
    errors: dict[str, list[float]] = {e: [] for e in engines}
    for runs in by_clip.values():
        if set(runs) != set(engines):
            continue
        common = set.intersection(*(set(runs[e]["recognize_matched"]) for e in engines))
        for e in engines:
            errors[e] += [err for i, err in zip(runs[e]["recognize_matched"],
                                                runs[e]["recognize_errors"], strict=True)
                          if i in common]
    if not errors or not all(errors.values()):
        return {}
    return {e: {"recognize_common_median_ms": _stat(np.asarray(v) * 1000, 50),
                "recognize_common_p90_ms": _stat(np.asarray(v) * 1000, 90),
                "recognize_common_n": len(v)} for e, v in errors.items()}


def _table(groups: dict[tuple[str, str], dict]) -> str:
    cols = [("align_per", "aPER", ".3f"), ("align_median_ms", "a med", ".1f"),
            ("align_p90_ms", "a p90", ".1f"), ("align_bias_ms", "a bias", ".1f"),
            ("onset_median_ms", "w on", ".1f"), ("onset_p90_ms", "w on90", ".1f"),
            ("offset_median_ms", "w off", ".1f"), ("offset_p90_ms", "w off90", ".1f"),
            ("recognize_per", "rPER", ".3f"), ("recognize_median_ms", "r med", ".1f"),
            ("recognize_p90_ms", "r p90", ".1f"), ("recognize_n", "r bnd", "d"),
            ("recognize_common_median_ms", "rc med", ".1f"),
            ("recognize_common_p90_ms", "rc p90", ".1f"), ("recognize_common_n", "rc bnd", "d"),
            ("align_s_per_s", "a s/s", ".3f"), ("recognize_s_per_s", "r s/s", ".3f")]
    head = f"{'data':<10} {'engine':<13} {'clips':>5} " + " ".join(f"{c[1]:>7}" for c in cols)
    lines = [head, "-" * len(head)]
    for (data, engine), s in groups.items():
        cells = []
        for key, _, fmt in cols:
            cells.append(f"{s[key]:>7{fmt}}" if key in s else f"{'-':>7}")
        lines.append(f"{data:<10} {engine:<13} {s['clips']:>5} " + " ".join(cells))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", nargs="+", choices=("synthetic", "emodb", "grid"),
                        default=["synthetic", "emodb", "grid"], help="data sets")
    parser.add_argument("--engines", nargs="+", choices=("auto", "hama", "pocketsphinx"),
                        default=["hama", "pocketsphinx"])
    parser.add_argument("--corpus", type=Path, help="an existing synthetic corpus folder")
    parser.add_argument("--shared", type=Path, default=SHARED,
                        help="folder holding emodb/ and grid/s1/ (../shared/data)")
    parser.add_argument("--sentences", type=int, default=40, help="sentences to generate")
    parser.add_argument("--parallel", type=int, default=10,
                        help="of which spoken in all five emotions")
    parser.add_argument("--seed", type=int, default=0, help="corpus seed")
    parser.add_argument("--workers", type=int, default=2, help="corpus generation workers")
    parser.add_argument("--limit", type=int, help="evaluate only the first N clips of each set")
    parser.add_argument("--json", type=Path, help="write the summary and per-clip rows here")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.ERROR,
                        format="%(levelname)s %(name)s: %(message)s")
    engines = _engines(args.engines)
    _warm(engines)
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="evalseg-") as tmp:
        if "synthetic" in args.data:
            folder = args.corpus
            if folder is None:
                folder = Path(tmp) / "corpus"
                config = CorpusConfig(sentences=args.sentences, parallel=args.parallel,
                                      variations=1, seed=args.seed)
                generate_corpus(folder, config, workers=args.workers)
            rows += _synthetic(folder, engines, args.limit)
    for name, reader, sub in (("emodb", _emodb, "emodb"), ("grid", _grid, "grid/s1")):
        if name in args.data:
            if not (args.shared / sub).is_dir():
                print(f"skipping {name}: {args.shared / sub} not found", file=sys.stderr)
                continue
            rows += reader(args.shared / sub, engines, args.limit)
    groups = {}
    for data in args.data:
        for engine in args.engines:
            part = [r for r in rows if r["data"] == data and r["engine"] == engine]
            if part:
                groups[(data, engine)] = summarize(part)
        if len(args.engines) > 1:
            common = common_onsets([r for r in rows if r["data"] == data], args.engines)
            for engine, stats in common.items():
                groups[(data, engine)].update(stats)
    print(_table(groups))
    print("aPER/rPER: phone error rate of alignment/recognition; a med/p90/bias: phone onset "
          "error of alignment (ms); w on/off: GRID word onset/offset error (ms); r med/p90: "
          "onset error of recognised phones matched to the reference (ms), r bnd: how many; "
          "rc med/p90/bnd: the same over the reference phones every engine matched; "
          "s/s: compute seconds per audio second")
    if args.json:
        args.json.write_text(json.dumps({"summary": {f"{d}/{e}": s for (d, e), s in
                                                     groups.items()}, "clips": rows}, indent=1))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
