"""Measures of facial motion: mouth opening and other distances, and errors against truth.

The measures follow the lip-sync literature: RMSE over channels, the *lip vertex error*
(for each frame the largest error over the lip points, averaged over frames), and the
Pearson correlation of mouth opening; the baselines' own measures (Hong et al. 2002
Eq. 6 and 8; Terissi et al. 2013 Eq. 11-12); and the facial measures an animator looks
at in a plot (mouth opening and width, brow height, the busiest curves).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from animegraph.motion.files import Motion

#: Point pairs whose distance is the mouth opening, per kind of database.
MOUTH_POINTS = {"markers": ("ulip_in_c", "llip_in_c"), "landmarks": ("lm13", "lm14")}
#: Curve names that are the mouth opening in curve databases (first present wins).
#: FACEGOOD's ``mouth_stretch_c`` (FACS AU27, mouth stretch) is its jaw opening.
MOUTH_CURVES = ("jaw", "jawOpen", "jaw_open", "JawOpen", "mouth_open", "mouthOpen",
                "mouth_stretch_c")


def _points(motion: np.ndarray, names: Sequence[str], label: str) -> np.ndarray:
    idx = [list(names).index(f"{label}.{a}") for a in "xyz"]
    return motion[:, idx]


def mouth_opening(motion: np.ndarray, names: Sequence[str], kind: str) -> np.ndarray:
    """Mouth opening over time: shape (n_frames,).

    Distance between the inner-lip midpoints for point databases; the jaw-open curve
    for curve databases.
    """
    if kind in MOUTH_POINTS:
        a, b = MOUTH_POINTS[kind]
        return np.linalg.norm(_points(motion, names, a) - _points(motion, names, b), axis=1)
    for name in MOUTH_CURVES:
        if name in names:
            return motion[:, list(names).index(name)]
    raise KeyError(f"no mouth-opening channel among {MOUTH_CURVES}")


def lip_channels(names: Sequence[str], groups: Sequence[str]) -> np.ndarray:
    """Indices of the channels of the lip motion group."""
    return np.array([i for i, g in enumerate(groups) if g == "lips"], dtype=np.int64)


def rmse(pred: np.ndarray, truth: np.ndarray, channels: np.ndarray | None = None) -> float:
    """Root-mean-square error over frames and ``channels`` (NaN in truth ignored)."""
    n = min(len(pred), len(truth))
    p, t = pred[:n], truth[:n]
    if channels is not None:
        p, t = p[:, channels], t[:, channels]
    return float(np.sqrt(np.nanmean((p - t) ** 2)))


def lip_vertex_error(pred: np.ndarray, truth: np.ndarray, names: Sequence[str],
                     groups: Sequence[str]) -> float:
    """Per frame the largest Euclidean error over the lip points, averaged over frames."""
    n = min(len(pred), len(truth))
    cols = [i for i, (nm, g) in enumerate(zip(names, groups, strict=True))
            if g == "lips" and nm.endswith((".x", ".y", ".z"))]
    if not cols:
        return float("nan")
    d = (pred[:n, cols] - truth[:n, cols]).reshape(n, -1, 3)
    err = np.linalg.norm(d, axis=2)
    return float(np.nanmean(np.nanmax(err, axis=1)))


def pearson(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson correlation of two curves over their common frames (NaN-safe)."""
    n = min(len(a), len(b))
    a, b = a[:n], b[:n]
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or np.std(a[ok]) == 0 or np.std(b[ok]) == 0:
        return float("nan")
    return float(np.corrcoef(a[ok], b[ok])[0, 1])



def motion_scores(pred: np.ndarray, truth: np.ndarray, names: Sequence[str],
                  groups: Sequence[str], kind: str, active: np.ndarray) -> dict:
    """Every measure of ``pred`` against ``truth`` (both (n_frames, n_channels)).

    ``active`` selects the channels that move in the database (RMSE "all" is over them).
    Point databases add the lip vertex error; curve databases report the jaw and mouth
    curves on their own.
    """
    lips = lip_channels(names, groups)
    out = {
        "rmse_all": rmse(pred, truth, active),
        "rmse_lips": rmse(pred, truth, lips) if len(lips) else float("nan"),
    }
    try:
        out["mouth_r"] = pearson(mouth_opening(pred, names, kind),
                                 mouth_opening(truth, names, kind))
    except KeyError:
        out["mouth_r"] = float("nan")
    if kind in MOUTH_POINTS:
        out["lve"] = lip_vertex_error(pred, truth, names, groups)
    else:
        jm = np.array([i for i, n in enumerate(names)
                       if n.lower().startswith(("jaw", "mouth")) and i in set(active)])
        out["rmse_jaw_mouth"] = rmse(pred, truth, jm) if len(jm) else float("nan")
        n = min(len(pred), len(truth))
        rs = [pearson(pred[:n, i], truth[:n, i]) for i in jm]
        out["r_jaw_mouth"] = float(np.nanmean(rs)) if rs else float("nan")
        rs = [pearson(pred[:n, i], truth[:n, i]) for i in active]
        out["r_all"] = float(np.nanmean(rs)) if rs else float("nan")
    return out



def paper_scores(pred: np.ndarray, truth: np.ndarray, active: np.ndarray, lips: np.ndarray,
                 norm: tuple[np.ndarray, np.ndarray]) -> dict:
    """The baselines' own measures of ``pred`` against ``truth`` (n_frames, n_channels).

    ``hong_r``, ``hong_nmse``: Hong et al. (2002) Eq. 6 and 8 over the ``active`` channels,
    normalised by ``norm`` = :func:`displacement_scale` of the training motion.
    ``amse``, ``acc``: Terissi et al. (2013) Eq. 11-12 over the active lip channels (the
    paper's visual parameters are mouth parameters; all active channels if none are lips).
    """
    n = min(len(pred), len(truth))
    pred, truth = pred[:n], truth[:n]
    center, scale = norm
    hp = hong_normalise(pred[:, active], center[active], scale[active])
    ht = hong_normalise(truth[:, active], center[active], scale[active])
    mouth = np.intersect1d(lips, active)
    mouth = mouth if len(mouth) else active
    return {"hong_r": hong_r(hp, ht), "hong_nmse": hong_nmse(hp, ht),
            "amse": amse(pred[:, mouth], truth[:, mouth]),
            "acc": acc(pred[:, mouth], truth[:, mouth])}



def _paired(pred: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pred = np.asarray(pred, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    if pred.ndim == 1:
        pred, truth = pred[:, None], truth[:, None]
    if pred.ndim != 2 or truth.ndim != 2 or pred.shape[1] != truth.shape[1]:
        raise ValueError(f"pred {pred.shape} and truth {truth.shape} must be (n_frames, "
                         "n_params) with the same n_params")
    n = min(len(pred), len(truth))
    return pred[:n], truth[:n]


def amse(pred: np.ndarray, truth: np.ndarray) -> float:
    """Average mean square error, Terissi et al. (2013) Eq. 11.

    ``ε = 1/(R T) Σ_r (1/σ²_r) Σ_t (õ_rt - o_rt)²``: the squared error of each visual
    parameter normalised by the variance ``σ²_r`` of its true values over the
    interval, averaged over parameters and frames (0 is perfect; predicting the true
    mean gives 1).

    Parameters
    ----------
    pred, truth : np.ndarray, shape (n_frames, n_params) or (n_frames,)
        Estimated and true parameters over their common frames. Parameters whose truth
        is constant (σ_r = 0) are left out; NaN values are ignored.

    Returns
    -------
    float
        NaN when no parameter varies.
    """
    p, t = _paired(pred, truth)
    var = np.nanvar(t, axis=0)
    keep = var > 0
    if not keep.any():
        return float("nan")
    return float(np.nanmean(np.nanmean((p[:, keep] - t[:, keep]) ** 2, axis=0) / var[keep]))


def acc(pred: np.ndarray, truth: np.ndarray) -> float:
    """Average correlation coefficient, Terissi et al. (2013) Eq. 12.

    ``ρ = 1/(R T) Σ_r Σ_t (o_rt - μ_r)(õ_rt - μ̃_r) / (σ_r σ̃_r)``: the Pearson
    correlation of each estimated parameter with its true values, averaged over
    parameters.

    Parameters
    ----------
    pred, truth : np.ndarray, shape (n_frames, n_params) or (n_frames,)
        Over their common frames; parameters where either series is constant are left
        out (see :func:`pearson`).

    Returns
    -------
    float
        NaN when no parameter has a defined correlation.
    """
    p, t = _paired(pred, truth)
    rs = [pearson(p[:, r], t[:, r]) for r in range(p.shape[1])]
    rs = [r for r in rs if np.isfinite(r)]
    return float(np.mean(rs)) if rs else float("nan")


def hong_normalise(motion: np.ndarray, center: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Displacements normalised as in Hong, Wen & Huang (2002) §VII-A.

    Each channel's displacement from ``center`` (the neutral or mean face) is divided by
    ``scale``, its largest absolute displacement in the training database, so that the
    database spans [-1, 1].

    Parameters
    ----------
    motion : np.ndarray, shape (n_frames, n_channels)
    center, scale : np.ndarray, shape (n_channels,)
        ``scale`` must be positive (leave constant channels out beforehand).
    """
    return (np.asarray(motion, dtype=np.float64) - center) / scale


def displacement_scale(train: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(center, scale)`` of :func:`hong_normalise` from training motion.

    ``center`` is the mean frame; ``scale`` each channel's largest absolute deviation
    from it (1 where a channel does not move).
    """
    train = np.asarray(train, dtype=np.float64)
    center = np.nanmean(train, axis=0)
    scale = np.nanmax(np.abs(train - center), axis=0)
    return center, np.where(scale > 0, scale, 1.0)


def hong_r(pred: np.ndarray, truth: np.ndarray) -> float:
    """Pearson product-moment correlation of Hong et al. (2002), Eq. 6.

    ``R = tr(Cov(d, d')) / sqrt(tr(Cov(d, d)) tr(Cov(d', d')))`` over frames, with ``d``
    the normalised ground truth and ``d'`` the normalised estimate, shape
    (n_frames, n_channels) (their common frames; rows with NaN are dropped).
    """
    n = min(len(pred), len(truth))
    p, t = np.asarray(pred[:n], np.float64), np.asarray(truth[:n], np.float64)
    ok = np.isfinite(p).all(axis=1) & np.isfinite(t).all(axis=1)
    p, t = p[ok] - p[ok].mean(axis=0), t[ok] - t[ok].mean(axis=0)
    den = np.sqrt(np.sum(t * t) * np.sum(p * p))
    return float(np.sum(t * p) / den) if den > 0 else float("nan")


def hong_nmse(pred: np.ndarray, truth: np.ndarray) -> float:
    """Mean square error of Hong et al. (2002), Eq. 8: ``E[||d - d'||^2 / gamma]`` on
    normalised data (gamma = number of channels), over the common frames."""
    n = min(len(pred), len(truth))
    d = np.asarray(pred[:n], np.float64) - np.asarray(truth[:n], np.float64)
    return float(np.nanmean(np.nanmean(d**2, axis=1)))


#: (label, point a, point b) distances per kind of point set; the first is the mouth.
POINT_MEASURES = {
    "markers": (("mouth opening (mm)", "ulip_in_c", "llip_in_c"),
                ("mouth width (mm)", "lip_corner_r", "lip_corner_l"),
                ("brow to eye (mm)", "brow_r1", "eye_in_r")),
    "landmarks": (("mouth opening (mm)", "lm13", "lm14"),
                  ("mouth width (mm)", "lm61", "lm291"),
                  ("brow to eye (mm)", "lm105", "lm159")),
}


def point_kind(names: Sequence[str]) -> str | None:
    """``markers`` or ``landmarks`` if the channels hold that point set, else None."""
    names = set(names)
    for kind, measures in POINT_MEASURES.items():
        if all(f"{p}.x" in names for _, a, b in measures[:1] for p in (a, b)):
            return kind
    return None


def _distance(values: np.ndarray, names: Sequence[str], a: str, b: str) -> np.ndarray:
    index = {n: i for i, n in enumerate(names)}
    pa = values[:, [index[f"{a}.{x}"] for x in "xyz"]]
    pb = values[:, [index[f"{b}.{x}"] for x in "xyz"]]
    return np.linalg.norm(pa - pb, axis=1)


def measures(values: np.ndarray, names: Sequence[str], kind: str | None = None,
             *, max_curves: int = 4, reference: Motion | None = None
             ) -> list[tuple[str, np.ndarray]]:
    """Facial measures over time: list of (label, values of shape (n_frames,)).

    Point sets: the distances of :data:`POINT_MEASURES` that the channels allow. Curves:
    the jaw/mouth-opening curve if there is one, then the busiest curves (busiest in
    ``reference`` when given, so two motions show the same curves).
    """
    kind = point_kind(names) if kind not in POINT_MEASURES else kind
    present = set(names)
    if kind in POINT_MEASURES:
        return [(label, _distance(values, names, a, b))
                for label, a, b in POINT_MEASURES[kind]
                if f"{a}.x" in present and f"{b}.x" in present]
    out = []
    mouth = next((n for n in MOUTH_CURVES if n in present), None)
    if mouth is not None:
        out.append((mouth, values[:, list(names).index(mouth)]))
    source = reference.values if reference is not None else values
    source_names = reference.names if reference is not None else names
    spread = np.nanstd(np.asarray(source, dtype=np.float64), axis=0)
    still = 1e-6 * max(float(np.nanmax(spread)), 1e-12) if len(spread) else 0.0
    for c in np.argsort(-spread):
        name = source_names[c]
        if name in present and name != mouth and len(out) < max_curves and spread[c] > still:
            out.append((name, values[:, list(names).index(name)]))
    return out


def measure(values: np.ndarray, names: Sequence[str], kind: str | None = None
            ) -> tuple[str, np.ndarray]:
    """The first of :func:`measures`: mouth opening where there is one."""
    found = measures(values, names, kind, max_curves=1)
    if not found:
        return "value", np.asarray(values, dtype=np.float64)
    return found[0]

