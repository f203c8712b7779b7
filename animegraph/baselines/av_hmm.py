"""``av-hmm``: a joint audio-visual HMM inverted to estimate visual features from speech.

After Terissi, Cerda, Gómez, Hitschfeld-Kahler & Girau, "A comprehensive system for facial
animation of generic 3D head models driven by speech", EURASIP J. Audio Speech Music
Process. 2013:5 (``../shared/papers/terissi2013-*.txt``).

* §3: the audio is framed at the video rate; the audio vector of frame ``t`` stacks the
  Mel-cepstra of frames ``t - tc .. t + tc`` (:data:`CONTEXT_FRAMES`, tc = 3); the visual
  vector holds a few mouth parameters (four Candide-3 animation units; here the first
  :data:`N_VISUAL` principal components of the motion).
* §4, §4.1: ONE ergodic HMM over the joint vector ``[o_a; o_v]``, N states with a mixture
  of M full-covariance Gaussians each (Eq. 1), trained by Baum–Welch (``hmmlearn``).
* §4.2: audio-to-visual conversion by HMM inversion: the visual sequence that maximises
  ``P(O_a, O_v | λ)`` (Eq. 2) is found by an EM iteration on the auxiliary function
  (Eq. 3-4) whose update is Eq. 7 — per frame, the precision-weighted combination of every
  (state, mixture) component's conditional visual mean, weighted by the posterior
  occupancies computed with the current estimate — repeated until it converges (Fig. 4).
* §6, Eq. 11-12: AMSE and ACC (:func:`animegraph.motion.measures.amse`, :func:`~.acc`).

:class:`AVHMM` is the model on plain arrays; the estimator that takes prepared clips and
audio is :class:`AVHMMBaseline`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy import linalg
from scipy.special import logsumexp

from animegraph.baselines.base import BaselineModel, fit_progress, sample_times
from animegraph.baselines.data import audio_features_at, resample_to
from animegraph.baselines.predicting import MAX_STORED_COUNT, MAX_STORED_RATE, check_stored_setting
from db.errors import DataError, ParameterError

# --- the paper's constants -------------------------------------------------------------
#: Mel-cepstral coefficients per audio frame: "the first eleven non-DC" (§6.1).
N_MFCC = 11
#: Co-articulation context tc, frames each side (§3; optimal value in §6.1.1 and §6.1.2).
CONTEXT_FRAMES = 3
#: Frame rate of the audio-visual features: the video rate, 30 fps (§3, §6.1).
FEATURE_FPS = 30.0
#: Visual parameters per frame: four mouth animation units of Candide-3 (§3, §6.1).
N_VISUAL = 4
#: States and mixtures of the sentence model shown in §6.1.2 / Fig. 8 (N = 28, M = 5).
N_STATES = 28
N_MIX = 5
#: The (N, M) grids of §6.1.1 (digits: N 2..19, M 3..20) and §6.1.2 (sentences:
#: N 8..40, M 2..7) — the sweep of ``scripts/sweep_av_hmm.py`` samples them.
SWEEP_DIGITS = {"n_states": (2, 19), "n_mix": (3, 20)}
SWEEP_SENTENCES = {"n_states": (8, 40), "n_mix": (2, 7)}

# --- ours (the paper gives none) ------------------------------------------------------
#: Baum–Welch: at most ``N_ITER`` iterations; stop when the training log-likelihood
#: gains less than ``TOL`` nats per frame (hmmlearn's ``tol`` is this times the frames).
N_ITER = 20
TOL = 1e-3
#: Added to the diagonal of every (standardised) covariance after each M-step, so that a
#: component with fewer frames than dimensions stays positive definite.
REG_COVAR = 1e-3
#: HMM inversion: at most this many Eq. 7 updates; stop when no visual value moves more
#: than ``INVERSION_TOL`` standard deviations.
INVERSION_MAX_ITER = 50
INVERSION_TOL = 1e-3
_LOG_2PI = math.log(2.0 * math.pi)


def n_free_parameters(n_states: int, n_mix: int, n_features: int) -> int:
    """Free scalars of an ergodic GMM-HMM with full covariances (hmmlearn's count).

    ``N - 1`` start, ``N(N - 1)`` transition, ``N(M - 1)`` mixture weights, ``NMd`` means
    and ``NMd(d + 1)/2`` covariances.
    """
    n, m, d = n_states, n_mix, n_features
    return (n - 1) + n * (n - 1) + n * (m - 1) + n * m * d + n * m * d * (d + 1) // 2


def _check_int(name: str, value: object, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
        raise ParameterError(f"{name} must be an integer >= {low}, got {value!r}")
    return int(value)


def _check_real(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating) or not (
        math.isfinite(value) and value > 0
    ):
        raise ParameterError(f"{name} must be a positive number, got {value!r}")
    return float(value)


def _hmm_class():
    """``hmmlearn.hmm.GMMHMM`` with a memory-lean full-covariance M-step (built lazily).

    It overrides hmmlearn's underscored EM hooks, which are not a public API: the
    dependency is pinned below 0.4, and ``test_em_step_through_hmmlearn_hooks_is_exact_em``
    checks one Baum-Welch step against stock ``GMMHMM`` and the EM update by hand.
    """
    from hmmlearn import hmm
    from hmmlearn.base import BaseHMM

    class _FullGMMHMM(hmm.GMMHMM):
        """GMMHMM whose covariance statistics are accumulated per component.

        hmmlearn 0.3 forms the (n_samples, N, M, d, d) outer products of every sequence
        at once (gigabytes for N = 28, M = 5, d = 81); here the second moments are
        summed per component with one matrix product, and the covariance M-step is the
        exact EM update ``Σ = E[x xᵀ] - μ μᵀ`` (plus ``reg_covar`` on the diagonal).
        """

        reg_covar = REG_COVAR
        _version = 0  # bumped whenever the parameters change
        _factors = None  # (version, whitening factors, log-determinants)
        _last = None  # (X, its component log densities) of the latest E-step sequence

        def _init(self, X, lengths=None):
            super()._init(X, lengths)
            self._version += 1

        def _component_log(self, X):
            """``log c_jk + log N(x_t; μ_jk, Σ_jk)``, shape (T, N, M); the Cholesky
            factors are computed once per parameter update, not once per sequence."""
            nc, nm, nf = self.n_components, self.n_mix, self.n_features
            if self._factors is None or self._factors[0] != self._version:
                cov = self.covars_.reshape(nc * nm, nf, nf)
                chol = np.linalg.cholesky(cov)
                inv = np.linalg.inv(chol)  # lower-triangular whitening factors
                logdet = 2.0 * np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(axis=1)
                # whitened (x - μ_c) = x L_c⁻ᵀ - μ_c L_c⁻ᵀ: one (T, d) x (d, C·d) product
                stacked = inv.transpose(2, 0, 1).reshape(nf, -1)
                offset = np.einsum("cij,cj->ci", inv, self.means_.reshape(nc * nm, nf))
                self._factors = (self._version, stacked, offset, logdet)
            _, stacked, offset, logdet = self._factors
            white = (X @ stacked).reshape(len(X), nc * nm, nf) - offset
            quad = np.einsum("tcd,tcd->tc", white, white)
            out = (-0.5 * (quad + logdet + nf * _LOG_2PI)
                   + np.log(np.maximum(self.weights_, 1e-300)).reshape(-1))
            return out.reshape(len(X), nc, nm)

        def _compute_log_likelihood(self, X):
            comp = self._component_log(X)
            self._last = (X, comp)
            return logsumexp(comp, axis=2)

        def _initialize_sufficient_statistics(self):
            stats = super()._initialize_sufficient_statistics()
            stats["xx"] = np.zeros((self.n_components, self.n_mix, self.n_features,
                                    self.n_features))
            return stats

        def _accumulate_sufficient_statistics(self, stats, X, lattice, post_comp,
                                              fwdlattice, bwdlattice):
            BaseHMM._accumulate_sufficient_statistics(self, stats, X, lattice, post_comp,
                                                      fwdlattice, bwdlattice)
            comp = self._last[1] if self._last and self._last[0] is X else (
                self._component_log(X))
            post_mix = np.exp(comp - logsumexp(comp, axis=2, keepdims=True))
            w = post_comp[:, :, None] * post_mix
            stats["post_mix_sum"] += w.sum(axis=0)
            stats["post_sum"] += post_comp.sum(axis=0)
            if "m" in self.params:
                stats["m_n"] += np.einsum("ijk,il->jkl", w, X)
            if "c" in self.params:
                outer = (X[:, :, None] * X[:, None, :]).reshape(len(X), -1)  # (T, d²)
                stats["xx"] += (w.reshape(len(X), -1).T @ outer).reshape(stats["xx"].shape)

        def _do_mstep(self, stats):
            params = self.params
            self.params = params.replace("c", "")
            try:
                super()._do_mstep(stats)
            finally:
                self.params = params
            self._version += 1
            if "c" not in params:
                return
            n = stats["post_mix_sum"]
            eye = np.eye(self.n_features)
            for j in range(self.n_components):
                for k in range(self.n_mix):
                    if n[j, k] < 1e-8:  # an unused component keeps its covariance
                        continue
                    mu = self.means_[j, k]
                    cov = stats["xx"][j, k] / n[j, k] - np.outer(mu, mu)
                    self.covars_[j, k] = 0.5 * (cov + cov.T) + self.reg_covar * eye
            self._version += 1

    return _FullGMMHMM


def forward_backward(log_b: np.ndarray, startprob: np.ndarray,
                     transmat: np.ndarray) -> tuple[np.ndarray, float]:
    """State posteriors of one sequence (scaled forward-backward, Rabiner 1989 §V.A).

    Parameters
    ----------
    log_b : np.ndarray, shape (T, N)
        Log emission densities ``log b_j(o_t)``.
    startprob : np.ndarray, shape (N,)
    transmat : np.ndarray, shape (N, N)

    Returns
    -------
    gamma : np.ndarray, shape (T, N)
        ``P(q_t = S_j | O, λ)``.
    log_likelihood : float
        ``log P(O | λ)``.
    """
    n_t, n = log_b.shape
    shift = log_b.max(axis=1, keepdims=True)
    # Floor at e^-700 (relative to the frame's best state): no frame can lose every state.
    b = np.exp(np.maximum(log_b - shift, -700.0))
    alpha = np.empty((n_t, n))
    scale = np.empty(n_t)
    a = startprob * b[0]
    scale[0] = a.sum()
    alpha[0] = a / scale[0]
    for t in range(1, n_t):
        a = (alpha[t - 1] @ transmat) * b[t]
        scale[t] = a.sum()
        alpha[t] = a / scale[t]
    beta = np.empty((n_t, n))
    beta[-1] = 1.0
    for t in range(n_t - 2, -1, -1):
        beta[t] = transmat @ (b[t + 1] * beta[t + 1]) / scale[t + 1]
    gamma = alpha * beta
    gamma /= gamma.sum(axis=1, keepdims=True)
    return gamma, float(np.log(scale).sum() + shift.sum())


class AVHMM:
    """A joint audio-visual HMM and its inversion (Terissi et al. 2013, §4).

    Parameters
    ----------
    n_states, n_mix : int, optional
        N ergodic states, M full-covariance Gaussians per state (§4; N = 28, M = 5 of
        §6.1.2).
    n_iter, tol : optional
        Baum–Welch iterations at most; stop when the log-likelihood gains less than
        ``tol`` nats per training frame.
    reg_covar : float, optional
        Added to the diagonal of every covariance of the standardised features.
    max_iter, inversion_tol : optional
        Inversion stopping rule: at most ``max_iter`` Eq. 7 updates, stop when no visual
        value changes by more than ``inversion_tol`` standard deviations.
    init : {"audio", "random"}, optional
        Starting point of the inversion. ``"random"`` is the paper's (§4.2, "initializing
        the visual observation randomly"): a draw from the training visual distribution.
        ``"audio"`` (default) replaces the first E-step's occupancies by those of the
        audio part alone (each Gaussian's audio marginal: the audio block of its mean and
        covariance), which is deterministic and needs no visual guess.
    random_state : int, optional
        Seeds the k-means initialisation of training and the ``"random"`` start.

    Attributes
    ----------
    startprob_ : np.ndarray, shape (N,)
    transmat_ : np.ndarray, shape (N, N)
    weights_ : np.ndarray, shape (N, M)
        Mixture coefficients ``c_jk`` (Eq. 1).
    means_ : np.ndarray, shape (N, M, Da + Dv)
    covars_ : np.ndarray, shape (N, M, Da + Dv, Da + Dv)
        Of the standardised joint vector (see ``feature_mean_``, ``feature_scale_``).
    n_audio_, n_visual_ : int
        Da and Dv.
    feature_mean_, feature_scale_ : np.ndarray, shape (Da + Dv,)
        The standardisation applied before training and undone after inversion.
    n_iter_ : int
        Eq. 7 updates made by the last :meth:`invert`.
    history_ : list of float
        ``log P(O_a, Õ_v | λ)`` after each update of the last :meth:`invert`.
    """

    def __init__(self, n_states: int = N_STATES, n_mix: int = N_MIX, *, n_iter: int = N_ITER,
                 tol: float = TOL, reg_covar: float = REG_COVAR,
                 max_iter: int = INVERSION_MAX_ITER, inversion_tol: float = INVERSION_TOL,
                 init: str = "audio", random_state: int = 0):
        self.n_states = n_states
        self.n_mix = n_mix
        self.n_iter = n_iter
        self.tol = tol
        self.reg_covar = reg_covar
        self.max_iter = max_iter
        self.inversion_tol = inversion_tol
        self.init = init
        self.random_state = random_state

    # ----------------------------------------------------------------------- training
    def _validate(self) -> None:
        _check_int("n_states", self.n_states, 1)
        _check_int("n_mix", self.n_mix, 1)
        _check_int("n_iter", self.n_iter, 1)
        _check_int("max_iter", self.max_iter, 1)
        _check_int("random_state", self.random_state, 0)
        for name in ("tol", "reg_covar", "inversion_tol"):
            _check_real(name, getattr(self, name))
        if self.init not in ("audio", "random"):
            raise ParameterError(f"init must be 'audio' or 'random', got {self.init!r}")

    def fit(self, sequences: Sequence[tuple[np.ndarray, np.ndarray]]) -> AVHMM:
        """Baum–Welch training on joint audio-visual sequences (§4.1).

        Parameters
        ----------
        sequences : sequence of (audio, visual)
            ``audio`` of shape (T_i, Da), ``visual`` of shape (T_i, Dv), frame-aligned.

        Raises
        ------
        ParameterError
            Bad hyper-parameters, shapes or dimensions that differ between sequences.
        DataError
            Non-finite values, or fewer observed values than free parameters
            (:func:`n_free_parameters`; hmmlearn's own degeneracy criterion).
        """
        self._validate()
        audio, visual, lengths = _stack(sequences)
        x = np.hstack([audio, visual])
        n_params = n_free_parameters(self.n_states, self.n_mix, x.shape[1])
        if x.size < n_params:
            raise DataError(
                f"av-hmm: {len(x)} frames x {x.shape[1]} features = {x.size} values, fewer "
                f"than the {n_params} free parameters of an AV-HMM with N={self.n_states} "
                f"states and M={self.n_mix} full-covariance mixtures; use more data or a "
                f"smaller model"
            )
        mean = x.mean(axis=0)
        scale = x.std(axis=0)
        scale[scale < 1e-12] = 1.0
        z = (x - mean) / scale
        model = _hmm_class()(
            n_components=self.n_states, n_mix=self.n_mix, covariance_type="full",
            n_iter=self.n_iter, tol=self.tol * len(z), min_covar=self.reg_covar,
            random_state=self.random_state,
        )
        model.reg_covar = self.reg_covar
        with fit_progress(self.n_iter, "av-hmm: Baum-Welch iterations") as bar:
            report = model.monitor_.report

            def counted(log_prob):  # hmmlearn's monitor hears every EM iteration
                report(log_prob)
                bar.update(1)
            model.monitor_.report = counted
            model.fit(z, lengths)
            model.monitor_.report = report
        self.n_audio_ = audio.shape[1]
        self.n_visual_ = visual.shape[1]
        self.feature_mean_ = mean
        self.feature_scale_ = scale
        self.startprob_ = np.asarray(model.startprob_, dtype=np.float64)
        self.transmat_ = np.asarray(model.transmat_, dtype=np.float64)
        self.weights_ = np.asarray(model.weights_, dtype=np.float64)
        self.means_ = np.asarray(model.means_, dtype=np.float64)
        self.covars_ = np.asarray(model.covars_, dtype=np.float64)
        self.train_log_likelihood_ = float(model.monitor_.history[-1])
        self.train_iter_ = int(model.monitor_.iter)
        self._prepare()
        return self

    def _prepare(self) -> None:
        """Pre-compute what inversion needs from each component (§6.3.2).

        With the precision ``Λ = Σ⁻¹`` partitioned into audio/visual blocks (Eq. 6), the
        audio marginal is ``N(o_a; μ^a, Σ^a)`` and the visual conditional has precision
        ``Λ^v`` and mean ``m(o_a) = μ^v - (Λ^v)⁻¹ Λ^va (o_a - μ^a)``.
        """
        da, dv = self.n_audio_, self.n_visual_
        c = self.n_states * self.n_mix
        cov = self.covars_.reshape(c, da + dv, da + dv)
        mu = self.means_.reshape(c, da + dv)
        self._mu_a = mu[:, :da]
        self._mu_v = mu[:, da:]
        self._chol_inv_a = np.empty((c, da, da))
        self._logdet_a = np.empty(c)
        self._prec_v = np.empty((c, dv, dv))
        self._prec_va = np.empty((c, dv, da))
        self._logdet_prec_v = np.empty(c)
        for i in range(c):
            chol = linalg.cholesky(cov[i, :da, :da], lower=True)
            self._chol_inv_a[i] = linalg.solve_triangular(chol, np.eye(da), lower=True)
            self._logdet_a[i] = 2.0 * np.log(np.diag(chol)).sum()
            prec = linalg.inv(cov[i])
            prec = 0.5 * (prec + prec.T)
            self._prec_v[i] = prec[da:, da:]
            self._prec_va[i] = prec[da:, :da]
            self._logdet_prec_v[i] = np.linalg.slogdet(self._prec_v[i])[1]
        self._log_weights = np.log(np.maximum(self.weights_, 1e-300)).reshape(c)

    # ---------------------------------------------------------------------- inversion
    def _audio_terms(self, audio_z: np.ndarray):
        """Audio log marginals (T, C), conditional means (T, C, Dv) and Eq. 7's numerator
        terms ``Λ^v μ^v - Λ^va (o_a - μ^a)`` (T, C, Dv) of one sequence."""
        da = self.n_audio_
        n_c = len(self._mu_a)
        diff = audio_z[None] - self._mu_a[:, None, :]  # (C, T, Da)
        # whitened (o_a - μ^a) as one (T, Da) x (Da, C·Da) product
        white = (audio_z @ self._chol_inv_a.transpose(2, 0, 1).reshape(da, -1)).reshape(
            len(audio_z), n_c, da) - np.einsum("cij,cj->ci", self._chol_inv_a, self._mu_a)
        log_a = -0.5 * (np.einsum("tcd,tcd->tc", white, white) + self._logdet_a
                        + da * _LOG_2PI)
        rhs = (np.einsum("cij,cj->ci", self._prec_v, self._mu_v)[:, None, :]
               - diff @ self._prec_va.transpose(0, 2, 1))  # (C, T, Dv)
        cond = np.linalg.solve(self._prec_v[:, None], rhs[..., None])[..., 0]
        return log_a, cond.transpose(1, 0, 2), rhs.transpose(1, 0, 2)

    def _component_log(self, log_a: np.ndarray, cond: np.ndarray,
                       visual_z: np.ndarray | None) -> np.ndarray:
        """``log c_jk + log N([o_a; o_v]; μ_jk, Σ_jk)``, shape (T, N, M); the audio
        marginal alone when ``visual_z`` is None."""
        out = log_a + self._log_weights
        if visual_z is not None:
            d = visual_z[:, None, :] - cond
            q = np.einsum("tci,cij,tcj->tc", d, self._prec_v, d)
            out = out - 0.5 * (q - self._logdet_prec_v + self.n_visual_ * _LOG_2PI)
        return out.reshape(len(out), self.n_states, self.n_mix)

    def _occupancy(self, comp_log: np.ndarray) -> tuple[np.ndarray, float]:
        """``P(q_t = j, k_t = k | O, λ)`` (T, N·M) and ``log P(O | λ)``."""
        state_log = logsumexp(comp_log, axis=2)
        gamma, loglik = forward_backward(state_log, self.startprob_, self.transmat_)
        within = np.exp(comp_log - state_log[:, :, None])
        return (gamma[:, :, None] * within).reshape(len(gamma), -1), loglik

    def _update(self, occ: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """Eq. 7: ``[Σ_jk γ Λ^v_jk]⁻¹ Σ_jk γ (Λ^v_jk μ^v_jk - Λ^va_jk (o_a - μ^a_jk))``."""
        lhs = np.einsum("tc,cij->tij", occ, self._prec_v)
        num = np.einsum("tc,tci->ti", occ, rhs)
        return np.linalg.solve(lhs, num[..., None])[..., 0]

    def _check_audio(self, audio: np.ndarray) -> np.ndarray:
        if not hasattr(self, "means_"):
            raise ParameterError("the AV-HMM is not fitted")
        audio = np.asarray(audio, dtype=np.float64)
        if audio.ndim != 2 or audio.shape[1] != self.n_audio_ or len(audio) == 0:
            raise ParameterError(
                f"audio must have shape (n_frames >= 1, {self.n_audio_}), got {audio.shape}")
        if not np.isfinite(audio).all():
            raise DataError("audio features hold NaN or infinite values")
        da = self.n_audio_
        return (audio - self.feature_mean_[:da]) / self.feature_scale_[:da]

    def invert(self, audio: np.ndarray) -> np.ndarray:
        """Visual features from audio features by HMM inversion (§4.2, Eq. 7, Fig. 4).

        Parameters
        ----------
        audio : np.ndarray, shape (T, Da)

        Returns
        -------
        np.ndarray, shape (T, Dv)
            ``Õ_v``, a (local) maximiser of ``P(O_a, O_v | λ)``. Each update is an exact
            maximisation of the auxiliary function (Eq. 3) in ``Õ_v``, so
            ``log P(O_a, Õ_v | λ)`` never decreases (``history_``).
        """
        self._validate()
        az = self._check_audio(audio)
        log_a, cond, rhs = self._audio_terms(az)
        if self.init == "random":
            rng = np.random.default_rng(self.random_state)
            vz = rng.standard_normal((len(az), self.n_visual_))
            occ, _ = self._occupancy(self._component_log(log_a, cond, vz))
        else:
            occ, _ = self._occupancy(self._component_log(log_a, cond, None))
        vz = self._update(occ, rhs)
        self.history_ = []
        self.n_iter_ = 1
        for _ in range(self.max_iter - 1):
            occ, loglik = self._occupancy(self._component_log(log_a, cond, vz))
            self.history_.append(loglik)
            new = self._update(occ, rhs)
            self.n_iter_ += 1
            moved = float(np.max(np.abs(new - vz)))
            vz = new
            if moved < self.inversion_tol:
                break
        self.history_.append(self._score_z(log_a, cond, vz))
        dv = slice(self.n_audio_, None)
        return vz * self.feature_scale_[dv] + self.feature_mean_[dv]

    def _score_z(self, log_a, cond, vz) -> float:
        return self._occupancy(self._component_log(log_a, cond, vz))[1]

    def score(self, audio: np.ndarray, visual: np.ndarray | None = None) -> float:
        """``log P(O_a, O_v | λ)``, or ``log P(O_a | λ)`` when ``visual`` is None.

        Of the standardised features (the standardisation adds a constant).
        """
        az = self._check_audio(audio)
        log_a, cond, _ = self._audio_terms(az)
        if visual is None:
            return self._occupancy(self._component_log(log_a, cond, None))[1]
        visual = np.asarray(visual, dtype=np.float64)
        if visual.shape != (len(az), self.n_visual_):
            raise ParameterError(f"visual must have shape {(len(az), self.n_visual_)}, "
                                 f"got {visual.shape}")
        dv = slice(self.n_audio_, None)
        vz = (visual - self.feature_mean_[dv]) / self.feature_scale_[dv]
        return self._score_z(log_a, cond, vz)

    # ------------------------------------------------------------------------ storage
    #: The fitted state: arrays of :meth:`to_arrays` besides the hyper-parameters.
    STATE = ("startprob_", "transmat_", "weights_", "means_", "covars_", "feature_mean_",
             "feature_scale_", "n_audio_")
    _PARAMS = ("n_states", "n_mix", "n_iter", "tol", "reg_covar", "max_iter",
               "inversion_tol", "random_state")

    def state_arrays(self) -> dict[str, np.ndarray]:
        """The fitted state (:data:`STATE`) as float arrays, names without the ``_``."""
        if not hasattr(self, "means_"):
            raise ParameterError("the AV-HMM is not fitted")
        return {name.rstrip("_"): np.asarray(getattr(self, name), dtype=np.float64)
                for name in self.STATE}

    def set_state(self, arrays) -> AVHMM:
        """Set the fitted state from :meth:`state_arrays` (hyper-parameters as constructed).

        Raises
        ------
        DataError
            Arrays missing or of shapes inconsistent with ``n_states`` and ``n_mix``.
        """
        try:
            for name in self.STATE[:-1]:
                setattr(self, name, np.asarray(arrays[name.rstrip("_")], dtype=np.float64))
            self.n_audio_ = int(np.asarray(arrays["n_audio"]))
        except KeyError as exc:
            raise DataError(f"av-hmm arrays lack {exc}") from None
        n, m = self.n_states, self.n_mix
        d = self.means_.shape[-1] if self.means_.ndim == 3 else -1
        self.n_visual_ = d - self.n_audio_
        shapes = {"startprob_": (n,), "transmat_": (n, n), "weights_": (n, m),
                  "means_": (n, m, d), "covars_": (n, m, d, d), "feature_mean_": (d,),
                  "feature_scale_": (d,)}
        bad = [k.rstrip("_") for k, s in shapes.items() if getattr(self, k).shape != s]
        if bad or self.n_visual_ < 1 or self.n_audio_ < 1:
            raise DataError(f"av-hmm arrays have inconsistent shapes: {bad}")
        try:
            self._prepare()
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise DataError(f"av-hmm covariances are not positive definite ({exc})") from None
        return self

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The fitted model with its hyper-parameters as named arrays (no pickles)."""
        out = self.state_arrays()
        out.update({name: np.asarray(getattr(self, name)) for name in self._PARAMS})
        out["init"] = np.asarray(self.init)
        return out

    @classmethod
    def from_arrays(cls, arrays) -> AVHMM:
        """Rebuild a model saved by :meth:`to_arrays`.

        Raises
        ------
        DataError
            Arrays missing or of inconsistent shapes.
        """
        try:
            kwargs = {name: np.asarray(arrays[name]).item() for name in cls._PARAMS}
            kwargs["init"] = str(arrays["init"])
        except KeyError as exc:
            raise DataError(f"av-hmm arrays lack {exc}") from None
        return cls(**kwargs).set_state(arrays)


def _stack(sequences) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Concatenate (audio, visual) pairs: (audio (T, Da), visual (T, Dv), lengths)."""
    if isinstance(sequences, tuple) and len(sequences) == 2 and isinstance(
            sequences[0], np.ndarray):
        raise ParameterError("sequences must be a list of (audio, visual) pairs")
    audio, visual, lengths = [], [], []
    for i, pair in enumerate(sequences):
        try:
            a, v = (np.asarray(x, dtype=np.float64) for x in pair)
        except (TypeError, ValueError):
            raise ParameterError(f"sequence {i} is not an (audio, visual) pair") from None
        if a.ndim != 2 or v.ndim != 2 or len(a) != len(v) or len(a) == 0:
            raise ParameterError(
                f"sequence {i}: audio {a.shape} and visual {v.shape} must be 2-D with the "
                f"same number (>= 1) of frames")
        if audio and (a.shape[1] != audio[0].shape[1] or v.shape[1] != visual[0].shape[1]):
            raise ParameterError(f"sequence {i}: dimensions {a.shape[1]}, {v.shape[1]} differ "
                                 f"from the first sequence's")
        if not (np.isfinite(a).all() and np.isfinite(v).all()):
            raise DataError(f"sequence {i} holds NaN or infinite values")
        audio.append(a)
        visual.append(v)
        lengths.append(len(a))
    if not audio:
        raise DataError("av-hmm: no training sequences")
    return np.vstack(audio), np.vstack(visual), np.asarray(lengths)


# ---------------------------------------------------------------------------------------
# The estimator on motion databases
# ---------------------------------------------------------------------------------------
class AVHMMBaseline(BaselineModel):
    """``av-hmm``: motion from speech by inverting one joint audio-visual HMM.

    Training (§3, §4.1): every clip is framed at ``feature_fps`` (the paper's video rate,
    30 fps); the audio vector of a frame stacks ``n_mfcc`` non-DC MFCCs of the frame and
    of ``context`` frames each side (:func:`.data.audio_features_at`, c0 dropped); the
    visual vector is the first ``n_visual`` principal components of the motion (the
    paper's four mouth parameters become the database's main motion modes). One
    :class:`AVHMM` is trained on all clips. Synthesis (§4.2): the visual components are
    estimated by HMM inversion, mapped back through the PCA and resampled to the motion
    frame rate. The method has no expression model; ``emotion`` is ignored.

    Parameters
    ----------
    n_states, n_mix : int, optional
        N and M (§6.1.2: N = 28, M = 5).
    n_mfcc, context : int, optional
        Cepstra per frame and tc (§6.1: 11, 3).
    feature_fps : float, optional
        Frame rate of the audio-visual features (§6.1: 30).
    n_visual : int, optional
        Visual parameters (§6.1: 4), here principal components of the motion.
    n_iter, tol, reg_covar, max_iter, inversion_tol, init, random_state : optional
        As for :class:`AVHMM`.

    Notes
    -----
    Fitting cost is dominated by the full covariances of d = 11·7 + 4 = 81 dimensions:
    each Baum–Welch iteration is O(T·N·M·d²). Timings: ``docs/results/lipsync.md``, "Baseline
    settings".
    """

    FIT_WHAT = ("Baum-Welch training of a 28-state audio-visual HMM on every clip: it can "
                "take minutes")


    method = "av-hmm"

    def __init__(self, n_states: int = N_STATES, n_mix: int = N_MIX, *, n_mfcc: int = N_MFCC,
                 context: int = CONTEXT_FRAMES, feature_fps: float = FEATURE_FPS,
                 n_visual: int = N_VISUAL, n_iter: int = N_ITER, tol: float = TOL,
                 reg_covar: float = REG_COVAR, max_iter: int = INVERSION_MAX_ITER,
                 inversion_tol: float = INVERSION_TOL, init: str = "audio",
                 random_state: int = 0):
        self.n_states = n_states
        self.n_mix = n_mix
        self.n_mfcc = n_mfcc
        self.context = context
        self.feature_fps = feature_fps
        self.n_visual = n_visual
        self.n_iter = n_iter
        self.tol = tol
        self.reg_covar = reg_covar
        self.max_iter = max_iter
        self.inversion_tol = inversion_tol
        self.init = init
        self.random_state = random_state

    def _hmm(self) -> AVHMM:
        return AVHMM(self.n_states, self.n_mix, n_iter=self.n_iter, tol=self.tol,
                     reg_covar=self.reg_covar, max_iter=self.max_iter,
                     inversion_tol=self.inversion_tol, init=self.init,
                     random_state=self.random_state)

    def _validate_features(self) -> None:
        _check_int("n_mfcc", self.n_mfcc, 1)
        if self.n_mfcc > 39:
            raise ParameterError(f"n_mfcc must be <= 39 (40 mel bands less c0), got "
                                 f"{self.n_mfcc}")
        _check_int("context", self.context, 0)
        _check_int("n_visual", self.n_visual, 1)
        _check_real("feature_fps", self.feature_fps)

    def audio_vectors(self, audio: np.ndarray, sample_rate: int,
                      times: np.ndarray) -> np.ndarray:
        """The audio observation ``o_a`` at ``times`` (§3).

        Returns
        -------
        np.ndarray, shape (len(times), n_mfcc * (2 * context + 1))
            Blocks of ``n_mfcc`` non-DC cepstra at offsets -tc .. tc frames.
        """
        width = self.n_mfcc + 1
        feats = audio_features_at(audio, sample_rate, times, n_mfcc=width,
                                  context=self.context,
                                  context_hop_s=1.0 / float(self.feature_fps))
        keep = np.arange(feats.shape[1]) % width != 0  # drop c0 of every block
        return feats[:, keep]

    def _fit(self, data) -> None:
        self._validate_features()
        self._hmm()._validate()
        rate = float(self.feature_fps)
        audio, motion = [], []
        with fit_progress(len(data.clips), "av-hmm: speech features") as bar:
            for clip, times, values in sample_times(data.clips, rate):
                audio.append(self.audio_vectors(clip.audio, clip.sample_rate, times))
                motion.append(values)
                bar.update(1)
        n_frames = sum(len(m) for m in motion)
        if n_frames <= self.n_visual:
            raise DataError(f"too little data for av-hmm: {n_frames} frames at {rate:g} fps "
                            f"for {self.n_visual} visual components")
        stacked = np.vstack(motion)
        self.motion_mean_ = stacked.mean(axis=0)
        _, sing, vt = np.linalg.svd(stacked - self.motion_mean_, full_matrices=False)
        n_vis = min(self.n_visual, len(sing))
        self.components_ = vt[:n_vis]
        self.explained_variance_ratio_ = sing[:n_vis] ** 2 / max((sing**2).sum(), 1e-300)
        visual = [(m - self.motion_mean_) @ self.components_.T for m in motion]
        self.hmm_ = self._hmm().fit(list(zip(audio, visual, strict=True)))

    def _predict(self, audio: np.ndarray, sample_rate: int, times: np.ndarray,
                 emotion: str | None) -> np.ndarray:
        rate = float(self.feature_fps)
        grid = np.arange(0.0, float(times[-1]) + 1.0 / rate, 1.0 / rate)
        visual = self.hmm_.invert(self.audio_vectors(audio, sample_rate, grid))
        motion = visual @ self.components_ + self.motion_mean_
        return resample_to(motion, rate, times)

    def _arrays(self) -> dict[str, np.ndarray]:
        return {**{f"hmm_{k}": v for k, v in self.hmm_.state_arrays().items()},
                "motion_mean": self.motion_mean_, "components": self.components_,
                "explained_variance_ratio": self.explained_variance_ratio_}

    def _restore(self, arrays: dict[str, np.ndarray]) -> None:
        try:
            self.motion_mean_ = np.asarray(arrays["motion_mean"], dtype=np.float64)
            self.components_ = np.asarray(arrays["components"], dtype=np.float64)
            self.explained_variance_ratio_ = np.asarray(arrays["explained_variance_ratio"])
        except KeyError as exc:
            raise DataError(f"stored av-hmm model lacks {exc}") from None
        # Checked before any prediction: stored settings are someone else's data (a context
        # of 10**9 frames, a feature rate of 0 Hz or 10**12 inversion steps would be a
        # hang or a crash); the features they give must be the HMM's audio dimension.
        self._validate_features()
        self._hmm()._validate()
        check_stored_setting("feature_fps", self.feature_fps, MAX_STORED_RATE)
        check_stored_setting("max_iter", self.max_iter, MAX_STORED_COUNT)
        self.hmm_ = self._hmm().set_state(
            {k[len("hmm_"):]: v for k, v in arrays.items() if k.startswith("hmm_")})
        if self.hmm_.n_audio_ != self.n_mfcc * (2 * self.context + 1):
            raise ValueError(f"{self.n_mfcc} cepstra with {self.context} frames of context do "
                             f"not fit the HMM's {self.hmm_.n_audio_} audio dimensions")
        if (self.components_.ndim != 2 or self.components_.shape[1] != len(self.channels_)
                or self.motion_mean_.shape != (len(self.channels_),)
                or self.components_.shape[0] != self.hmm_.n_visual_):
            raise DataError("stored av-hmm model: PCA and channels do not match")
