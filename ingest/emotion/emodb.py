"""The Berlin Emotional Speech Database (EmoDB) reader, for evaluation and tests.

The copy in ``../shared/data/emodb`` is cut: every file is 22.05 kHz and exactly 2.0 s
long (read its README) -- figures on it are not comparable with published EmoDB figures.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from db.errors import DataError

__all__ = ["EMODB_EMOTIONS", "load_emodb"]

#: EmoDB file-name emotion letters (German initials) to English names.
EMODB_EMOTIONS = {
    "W": "anger",
    "L": "boredom",
    "E": "disgust",
    "A": "fear",
    "F": "happiness",
    "T": "sadness",
    "N": "neutral",
}
_EMODB_NAME = re.compile(r"^(\d\d)([a-z]\d\d)([WLEAFTN])([a-z])$")


def load_emodb(root) -> tuple[list[tuple[np.ndarray, int]], np.ndarray, np.ndarray]:
    """Read the Berlin Emotional Speech Database (EmoDB).

    File names are ``SSTTTEV.wav``: speaker (2 digits), text code (3), emotion letter
    (W anger, L boredom, E disgust, A fear, F happiness, T sadness, N neutral) and
    version letter.

    Parameters
    ----------
    root : path-like
        The EmoDB folder (holding ``wav/``) or the ``wav`` folder itself.

    Returns
    -------
    utterances : list of (np.ndarray, int)
        ``(audio, sample_rate)`` per file in sorted file-name order; audio float32, shape
        (n_samples,).
    labels : np.ndarray of str, shape (n_files,)
        English emotion names.
    speakers : np.ndarray of str, shape (n_files,)
        Two-digit speaker codes.

    Raises
    ------
    DataError
        No files, a file name that is not EmoDB's, or a file
        :func:`ingest.formats.wav.read_wav` refuses (its one line).
    """
    from ingest.formats.wav import read_wav  # the bounds and checks of any speech read

    root = Path(root)
    wav = root / "wav" if (root / "wav").is_dir() else root
    files = sorted(wav.glob("*.wav"))
    if not files:
        raise DataError(f"no EmoDB .wav files in {wav}")
    utterances, labels, speakers = [], [], []
    for f in files:
        m = _EMODB_NAME.match(f.stem)
        if m is None:
            raise DataError(f"not an EmoDB file name: {f.name}")
        utterances.append(read_wav(f))
        labels.append(EMODB_EMOTIONS[m.group(3)])
        speakers.append(m.group(1))
    return utterances, np.array(labels), np.array(speakers)
