"""How well the music check tells real music from real speech
(docs/results/robustness.md, "Speech input checks").

Usage::

    python scripts/eval_music.py [--shared ../shared/data] [--music DIR] [--phones]

Prints, per set of recordings, how many :func:`ingest.speech.quality.assess` calls music
(:data:`~ingest.speech.quality.MUSIC_LOW_ENERGY`, :data:`~ingest.speech.quality.MUSIC_PULSE`)
and the range of both measures: on real speech a warning is a false alarm, on music a
detection. With ``--phones`` also the hama phone rate's warning
(:data:`~ingest.speech.quality.MIN_PHONE_RATE`) and the share either check warns (slow: the
recogniser hears every excerpt, about 0.15 x real time).

Speech (all real, from ``--shared``): every GRID s1 clip (3 s), every EmoDB clip (2 s),
FACEGOOD, talkingface and the Live Link take whole and cut into 3, 5 and 10 s at random;
every fourth GRID clip in white noise at 10 dB SNR, in pink noise at 5 dB, and every eighth
with reverberation of RT60 0.5 and 1 s (exponentially decaying noise as the room's impulse
response); eSpeak NG sentences, as the tests speak them.

Music (real, from Debian's packages; skipped when ``--music`` holds none of them). The
figures in the module docstring of :mod:`ingest.speech.quality` were measured on these
(bookworm; ``apt-get download PKG`` then ``dpkg -x PKG_*.deb MUSIC/PKG``, one folder per
package under ``--music``; about 600 MB of packages, no install needed):

=============================  ===================  ======================================
package (version)              kind                 files used, licence
=============================  ===================  ======================================
wesnoth-1.16-music 1.16.9-1    orchestral           41 ``*.ogg``; GPL-2+
warzone2100-music 4.3.3-3      electronic (drums)   30 ``*.opus``; GPL-2+
nexuiz-music 2.5.2-12          electronic (drums)   18 ``*.ogg`` in ``music.pk3``; GPL-2+
drascula-music 1.0+ds4-2       game (adventure)     31 ``audio/track*.ogg``; BSD-like
fretsonfire-songs-muldjord 2   rock / metal         4 songs: ``song.ogg`` + ``guitar.ogg``
  .dfsg-2.1                                         mixed; CC BY-SA 3.0
fretsonfire-songs-sectoid 1    rock / metal         4 songs, as above; MIT-style
  .dfsg-3.1
csmash-demosong 1.4+nmu2       pop                  ``danslatristesse2-48.ogg``; EFF OAL 1.0
sonic-pi-samples 3.2.2~repack  drum loops (played)  17 ``loop_*.flac`` (amen break, tabla
  -8                                                ...), repeated to 12 s; mostly CC0
hydrogen-drumkits 2017.09.19   drum loops           kick, snare and hat samples of its 14
  ~dfsg-1                      (assembled)          kits on an eighth-note grid, 80-160
                                                    bpm, 3 patterns a kit; GPL-2 / CC-BY
sonic-pi-samples, lmms-common  voices (choir)       ``ambi_choir``; lmms' ``*choir*``,
  1.2.2+dfsg1-6                                     ``*chorus*`` samples, repeated;
                                                    CC0 / GPL-2+
=============================  ===================  ======================================

Each music file gives two excerpts of each length (3, 5 and 10 s) at random places, as a
user would pass a clip; excerpts quieter than -50 dBFS are skipped. No song with lead vocals
was found in Debian's packages: sung music (the hard case) is measured only by the choir
samples.
"""

from __future__ import annotations

import argparse
import io
import re
import sys
import time
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Iterator
from math import gcd
from pathlib import Path

import numpy as np
from scipy.signal import fftconvolve, resample_poly

from ingest.formats.media import read_audio
from ingest.speech import quality

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
RATE = 16000
LENGTHS = (3.0, 5.0, 10.0)


def _mono16k(data: np.ndarray, rate: int) -> np.ndarray:
    x = data.mean(axis=1) if data.ndim == 2 else data
    x = np.asarray(x, dtype=np.float64)
    if rate != RATE:
        g = gcd(RATE, rate)
        x = resample_poly(x, RATE // g, rate // g)
    return x


def _at_16k(path: Path) -> np.ndarray:
    x, rate = read_audio(path, RATE) if path.suffix != ".wav" else read_audio(path)
    return _mono16k(x, rate)


def _cuts(x: np.ndarray, rng: np.random.Generator, per: int) -> Iterator[tuple[float, np.ndarray]]:
    """``per`` random excerpts of each of LENGTHS (s) that are not near silence."""
    for seconds in LENGTHS:
        n = int(seconds * RATE)
        if len(x) < n:
            continue
        got = 0
        for _ in range(5 * per):
            start = int(rng.integers(0, len(x) - n + 1))
            piece = x[start:start + n]
            if np.sqrt(np.mean(piece ** 2)) < 10 ** (-50 / 20):
                continue
            yield seconds, piece
            got += 1
            if got == per:
                break


# ---------------------------------------------------------------------------------------------
# speech
# ---------------------------------------------------------------------------------------------


def room_impulse(rng: np.random.Generator, rt60: float) -> np.ndarray:
    """A room's impulse response: noise decaying 60 dB in ``rt60`` s after the direct sound."""
    t = np.arange(int(rt60 * RATE)) / RATE
    h = rng.standard_normal(t.size) * np.exp(-6.9 * t / rt60)
    h[0] = 1.0
    return h / np.sqrt(np.sum(h ** 2))


def speech(shared: Path, rng: np.random.Generator) -> Iterator[tuple[str, np.ndarray]]:
    grid = sorted((shared / "grid" / "s1").glob("*.mp4"))
    for path in grid:
        yield "GRID (3 s)", _at_16k(path)
    for path in sorted((shared / "emodb" / "wav").glob("*.wav")):
        yield "EmoDB (2 s)", _at_16k(path)
    talking = sorted((shared / "talkingface").glob("*/audio_16k.wav"))
    long = ([("FACEGOOD", p, 12) for p in sorted((shared / "facegood" / "wav").glob("*.wav"))]
            + [("talkingface", p, 4) for p in talking]
            + [("Live Link", p, 4) for p in sorted((shared / "livelink").glob("*.wav"))])
    for name, path, per in long:
        x = _at_16k(path)
        yield f"{name} (whole)", x
        for seconds, piece in _cuts(x, rng, per):
            yield f"{name} ({seconds:g} s cuts)", piece
    for path in grid[::4]:
        x = _at_16k(path)
        power = np.mean(x ** 2)
        yield "GRID + white noise 10 dB", x + rng.standard_normal(x.size) * np.sqrt(power / 10)
        spectrum = np.fft.rfft(rng.standard_normal(x.size))
        spectrum[1:] /= np.sqrt(np.fft.rfftfreq(x.size, 1 / RATE)[1:])
        spectrum[0] = 0
        pink = np.fft.irfft(spectrum, x.size)
        yield "GRID + pink noise 5 dB", x + pink / pink.std() * np.sqrt(power / 10 ** 0.5)
    for path in grid[2::8]:
        x = _at_16k(path)
        for rt60 in (0.5, 1.0):
            yield (f"GRID, reverberation {rt60:g} s",
                   fftconvolve(x, room_impulse(rng, rt60))[: x.size])
    for path in sorted((shared / "talkingface").glob("*/audio_16k.wav")):
        x = _at_16k(path)
        y = fftconvolve(x, room_impulse(rng, 1.0))[: x.size]
        for start in range(0, y.size - 5 * RATE, 5 * RATE):
            yield "talkingface, reverberation 1 s (5 s)", y[start:start + 5 * RATE]


def espeak() -> Iterator[tuple[str, np.ndarray]]:
    try:
        from ingest.speech.espeak import Voice, speak
    except ImportError:  # pragma: no cover - eSpeak NG is a dependency
        return
    texts = ("The quick brown fox jumps over the lazy dog near the river bank.",
             "Bob paid the big puppy a bit of apple pie. Maybe the boy bought a bubble pipe.",
             "Bin blue at F two now.", "Something else, louder and faster!",
             "Bob moved the warm vase away.", "Whispers in the wind")
    voices = (Voice(), Voice(name="en-us+m3"), Voice(rate=120),
              Voice(name="en-us+klatt", rate=300, volume=180))
    for text in texts:
        for voice in voices:
            utt = speak(text, voice)
            yield "eSpeak NG sentences", _mono16k(utt.audio, utt.sample_rate)


# ---------------------------------------------------------------------------------------------
# music
# ---------------------------------------------------------------------------------------------


def _decode(source) -> np.ndarray:
    import soundfile

    data, rate = soundfile.read(source, dtype="float32", always_2d=True)
    return _mono16k(data, rate)


def _repeated(x: np.ndarray, seconds: float = 12.0) -> np.ndarray:
    return np.tile(x, int(np.ceil(seconds * RATE / max(x.size, 1))))


def _drum_loops(kits: Path, rng: np.random.Generator) -> Iterator[np.ndarray]:
    """hydrogen-drumkits' kick, snare and hat samples on an eighth-note grid, 12 s each."""
    wanted = ((r"kick|bass ?drum|djembe.*bass|cajon thump|bongo lo"),
              (r"snare|clap|djembe.*slap|cajon slap"),
              (r"hat|hh|ride|maraca|shaker|tambourine|djembe.*tone"))
    for kit in sorted(p.parent for p in kits.rglob("drumkit.xml")):
        sounds: dict[str, Path] = {}
        for inst in ET.parse(kit / "drumkit.xml").getroot().iter():
            if inst.tag.split("}")[-1] != "instrument":
                continue
            name = next((c.text or "" for c in inst if c.tag.split("}")[-1] == "name"), "")
            files = [c.text for c in inst.iter() if c.tag.split("}")[-1] == "filename" and c.text]
            if files:
                sounds[name] = kit / files[-1]
        for pattern in range(3):
            parts = []
            for regex in wanted:
                found = [p for n, p in sounds.items() if re.search(regex, n, re.I)]
                parts.append(_decode(found[rng.integers(len(found))]) if found else None)
            kick, snare, hat = parts
            if kick is None and snare is None:
                continue
            step = 60 / rng.uniform(80, 160) / 2
            x = np.zeros(14 * RATE)
            for i in range(int(12 / step)):
                at, beat = int(i * step * RATE), i % 8
                hits = [(kick, 1.0)] if beat in (0, 4) or (pattern == 1 and beat == 5) else []
                hits += [(snare, 0.9)] if beat in (2, 6) else []
                hits += [(hat, 0.5 * rng.uniform(0.7, 1))] if pattern != 2 or beat % 2 == 0 else []
                for sound, gain in hits:
                    if sound is not None:
                        m = min(sound.size, x.size - at)
                        x[at:at + m] += gain * sound[:m]
            x = x[: 12 * RATE]
            yield 0.7 * x / max(np.abs(x).max(), 1e-9)


def music(root: Path, rng: np.random.Generator) -> Iterator[tuple[str, np.ndarray]]:
    def files(package: str, pattern: str) -> list[Path]:
        if not (root / package).is_dir():
            return []
        return sorted(p for p in (root / package).rglob(pattern) if not p.is_symlink())

    tracks: list[tuple[str, object]] = []
    tracks += [("orchestral (wesnoth)", p) for p in files("wesnoth-1.16-music", "*.ogg")]
    tracks += [("electronic (warzone2100)", p) for p in files("warzone2100-music", "*.opus")]
    for pk3 in files("nexuiz-music", "*.pk3"):
        with zipfile.ZipFile(pk3) as z:
            tracks += [("electronic (nexuiz)", io.BytesIO(z.read(i)))
                       for i in z.infolist() if i.filename.endswith(".ogg")]
    tracks += [("game (drascula)", p) for p in files("drascula-music", "*.ogg")]
    tracks += [("pop (csmash)", p) for p in files("csmash-demosong", "*.ogg")]
    for name, source in tracks:
        for _, piece in _cuts(_decode(source), rng, 2):
            yield name, piece
    for package in ("fretsonfire-songs-muldjord", "fretsonfire-songs-sectoid"):
        for song in files(package, "song.ogg"):
            parts = [_decode(song)] + ([_decode(song.parent / "guitar.ogg")]
                                       if (song.parent / "guitar.ogg").is_file() else [])
            x = np.zeros(max(p.size for p in parts))
            for p in parts:
                x[: p.size] += p
            for _, piece in _cuts(x / max(1.0, np.abs(x).max()), rng, 2):
                yield "rock / metal (fretsonfire)", piece
    for path in files("sonic-pi-samples", "loop_*.flac"):
        for _, piece in _cuts(_repeated(_decode(path)), rng, 1):
            yield "drum loops, played (sonic-pi)", piece
    if (root / "hydrogen-drumkits").is_dir():
        for loop in _drum_loops(root / "hydrogen-drumkits", rng):
            for _, piece in _cuts(loop, rng, 1):
                yield "drum loops, assembled (hydrogen)", piece
    voices = files("sonic-pi-samples", "ambi_choir.flac") + [
        p for p in files("lmms-common", "*.ogg") if re.search("choir|chorus", p.name)]
    for path in voices:
        for _, piece in _cuts(_repeated(_decode(path)), rng, 1):
            yield "voices (choir samples)", piece


# ---------------------------------------------------------------------------------------------
# report
# ---------------------------------------------------------------------------------------------


def _said(q: quality.AudioQuality) -> bool:
    return any("sounds like music" in line for line in quality.warnings_for(q))


def _phones(q: quality.AudioQuality) -> bool:
    return q.phone_rate is not None and q.phone_rate < quality.MIN_PHONE_RATE


def _range(values: list) -> str:
    v = np.asarray([x for x in values if x is not None], dtype=float)
    return f"{v.min():5.2f} {np.median(v):5.2f} {v.max():5.2f}" if v.size else " " * 17


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=SHARED)
    parser.add_argument("--music", type=Path, default=None,
                        help="folder of the extracted Debian packages (one folder each; "
                             "without it, speech only)")
    parser.add_argument("--phones", action="store_true",
                        help="also the hama phone rate's warning (slow)")
    args = parser.parse_args()
    ctc = None
    if args.phones:
        from ingest.speech import ctc
    rng = np.random.default_rng(0)
    print(f"{'audio':<40} {'n':>5} {'music':>10} {'low energy min/med/max':>23} "
          f"{'pulse min/med/max':>18}" + (f" {'phones<4':>9} {'either':>9}" if ctc else ""))
    totals = {"speech": [0, 0, 0, 0], "music": [0, 0, 0, 0]}
    spent, heard = 0.0, 0.0
    for side, source in (("speech", speech(args.shared, rng)), ("speech", espeak()),
                         ("music", music(args.music, rng) if args.music else iter(()))):
        rows: dict[str, list] = {}
        for name, x in source:
            q = quality.assess(x.astype(np.float32), RATE)
            y = x.astype(np.float32).astype(np.float64)  # as assess() has it
            t = time.perf_counter()  # the music measures' own cost
            quality._low_energy(y, RATE)
            quality._pulse(y, RATE)
            spent, heard = spent + time.perf_counter() - t, heard + x.size / RATE
            if ctc is not None:
                probs = ctc.posteriors(x.astype(np.float32), RATE)
                q = quality.assess(x.astype(np.float32), RATE, probs)
            rows.setdefault(name, []).append(q)
        for name, qs in rows.items():
            said, phones = sum(map(_said, qs)), sum(map(_phones, qs))
            either = sum(_said(q) or _phones(q) for q in qs)
            for i, v in enumerate((len(qs), said, phones, either)):
                totals[side][i] += v
            print(f"{name:<40} {len(qs):>5} {said:>4} {100 * said / len(qs):>4.0f} % "
                  f"{_range([q.low_energy for q in qs]):>23} {_range([q.pulse for q in qs]):>18}"
                  + (f" {phones:>4} {100 * phones / len(qs):>3.0f}%"
                     f" {either:>4} {100 * either / len(qs):>3.0f}%" if ctc else ""), flush=True)
    for side, (n, said, phones, either) in totals.items():
        if n:
            print(f"{side} in all: {said}/{n} called music"
                  + (f", {phones} by the phone rate, {either} by either" if ctc else ""))
    if not totals["music"][0]:
        print(f"no music under {args.music}: see this script's docstring for the packages")
    if heard:
        print(f"cost of the music measures: {1000 * spent / heard:.2f} ms per second of audio")
    return 0


if __name__ == "__main__":
    sys.exit(main())
