"""The fits of the audio-only guides (mu-mlp, ppg-ridge) on a database, as ``ingest`` does
them after it writes (:func:`animegraph.apps.prepare.fit_guides`).

Usage::

    python scripts/bench_guide_fit.py DB [--previous] [--rehear]

Prints the database's clips, minutes of speech and clips with usable stored posteriors
(:func:`animegraph.baselines.ppg_forward.stored_posteriors`), the load average, then the
wall and CPU seconds of reading the clips once and of each guide's fit with its default
settings. ``--previous`` also fits each with the settings before the fast defaults
(mu-mlp trained in float64, ppg-ridge trying every penalty) and says how far apart the
two fits are. ``--rehear`` also fits ppg-ridge with the stored CTC blank dropped (a
database built before it was stored: hama hears every clip again; its remembered outputs
are forgotten first) and compares its coefficients (the stored values are float16).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

import numpy as np

from animegraph.baselines.data import training_set
from animegraph.baselines.mu_mlp import MuMlp
from animegraph.baselines.ppg_forward import stored_posteriors
from animegraph.baselines.ppg_ridge import PpgRidge
from ingest.speech import ctc


def timed(label: str, work):
    ctc.forget()
    t0, c0 = time.perf_counter(), os.times()
    out = work()
    c1 = os.times()
    print(f"{label}: {time.perf_counter() - t0:.1f} s wall, "
          f"{c1.user - c0.user + c1.system - c0.system:.1f} s CPU"
          + (f", penalty {out.alpha_:g}" if isinstance(out, PpgRidge) else ""), flush=True)
    return out


def apart(a: np.ndarray, b: np.ndarray) -> str:
    return f"{np.abs(a - b).max() / np.abs(b).max():.2%} of the largest"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db")
    parser.add_argument("--previous", action="store_true",
                        help="also fit with the settings before the fast defaults")
    parser.add_argument("--rehear", action="store_true",
                        help="also fit ppg-ridge with hama hearing every clip again")
    args = parser.parse_args(argv)
    print(f"load average {' '.join(f'{v:.1f}' for v in os.getloadavg())}, "
          f"{os.cpu_count()} CPUs", flush=True)
    data = timed("reading the clips", lambda: training_set(args.db))
    minutes = sum(len(c.audio) / c.sample_rate for c in data.clips) / 60
    usable = sum(stored_posteriors(c) is not None for c in data.clips)
    print(f"{len(data.clips)} clips, {minutes:.1f} min of speech, {usable} with stored "
          f"posteriors, {len(data.names)} channels", flush=True)
    mu = timed("mu-mlp", lambda: MuMlp().fit(data))
    ppg = timed("ppg-ridge", lambda: PpgRidge().fit(data))
    if args.previous:
        wide = timed("mu-mlp, mlp_dtype='float64'", lambda: MuMlp(mlp_dtype="float64").fit(data))
        clip = data.clips[0]
        a, b = (m.predict(clip.audio, clip.sample_rate) for m in (mu, wide))
        print(f"  their predictions for {clip.clip_id}: {apart(a, b)} value apart", flush=True)
        every = timed("ppg-ridge, alpha_search='all'",
                      lambda: PpgRidge(alpha_search="all").fit(data))
        print(f"  coefficients {apart(ppg.coef_, every.coef_)} coefficient apart", flush=True)
    if args.rehear:
        again = timed("ppg-ridge, hama hearing every clip again", lambda: PpgRidge().fit(
            dataclasses.replace(data, clips=tuple(
                dataclasses.replace(c, posterior_blank=None) for c in data.clips))))
        print(f"  coefficients {apart(ppg.coef_, again.coef_)} coefficient apart", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
