"""ppg-ridge's fit on a database: with the posteriors ingest stored, and with hama hearing
every clip again.

Usage::

    python scripts/bench_guide_fit.py DB

Prints the database's clips, minutes of speech and clips with usable stored posteriors
(:func:`animegraph.baselines.ppg_forward.stored_posteriors`), then the wall and CPU
seconds of ``PpgRidge().fit`` twice: as a first audio-only ``synth`` does it, and with the
stored CTC blank dropped (a database built before it was stored: hama hears every clip
again; its remembered outputs are forgotten first). Last, how far apart the two fits'
coefficients are (the stored values are float16).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

import numpy as np

from animegraph.baselines.data import training_set
from animegraph.baselines.ppg_forward import stored_posteriors
from animegraph.baselines.ppg_ridge import PpgRidge
from ingest.speech import ctc


def timed_fit(data, label: str) -> PpgRidge:
    ctc.forget()
    t0, c0 = time.perf_counter(), os.times()
    model = PpgRidge().fit(data)
    c1 = os.times()
    print(f"{label}: {time.perf_counter() - t0:.1f} s wall, "
          f"{c1.user - c0.user + c1.system - c0.system:.1f} s CPU, penalty {model.alpha_:g}")
    return model


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db")
    args = parser.parse_args(argv)
    data = training_set(args.db)
    minutes = sum(len(c.audio) / c.sample_rate for c in data.clips) / 60
    usable = sum(stored_posteriors(c) is not None for c in data.clips)
    print(f"{len(data.clips)} clips, {minutes:.1f} min of speech, {usable} with stored "
          "posteriors")
    stored = timed_fit(data, "with the stored posteriors")
    again = timed_fit(dataclasses.replace(data, clips=tuple(
        dataclasses.replace(c, posterior_blank=None) for c in data.clips)),
        "hama hearing every clip again")
    scale = np.abs(again.coef_).max()
    print(f"largest coefficient difference: {np.abs(stored.coef_ - again.coef_).max() / scale:.2%}"
          " of the largest coefficient")
    return 0


if __name__ == "__main__":
    sys.exit(main())
