"""Jam-count hypotheses: an interacting multiple model (IMM) over filterpy Kalman filters.

Hypothesis k says "k rollers are jammed"; each has its own filter over the continuous state
(load, load rate, ripple) and a probability. One step per block, as in the IMM of Blom and
Bar-Shalom (the equations of filterpy's ``IMMEstimator``):

1. mixing: c_j = sum_i pi_ij mu_i, x0_j = sum_i pi_ij mu_i x_i / c_j, P0_j likewise plus the
   spread of the means; jams only ever increase, so pi is upper bidiagonal over one block:
   pi_{k,k} = 1 - p, pi_{k,k+1} = p with p = 1 - exp(-rate dt). A jump k -> k + 1 adds a
   ripple of unknown phase: its covariance (ripple_prior_std^2 on c and s) is added;
2. each filter predicts and updates (filterpy ``ExtendedKalmanFilter`` or
   ``UnscentedKalmanFilter``; Joseph-form covariance update in the EKF);
3. mu_j proportional to c_j times the measurement likelihood N(y; 0, S_j). At standstill the
   likelihoods are not used: the stiction band carries no evidence about jams.

What filterpy's ``IMMEstimator`` does not do and this does: pruning (a hypothesis below
``filter.min_hypothesis_probability`` is dropped, and only the next count above the plausible
ones is kept to catch a new jam), gating (a block that no hypothesis explains is not used),
and numerical repair of the covariances (symmetrised, variance floors, positive definite).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
from numpy.typing import NDArray

from prsm_health.estimation.inputs import Block
from prsm_health.estimation.measurement import (
    LOAD,
    LOAD_ACCELERATION,
    LOAD_RATE,
    LOAD_STATES,
    RIPPLE_COS,
    Prediction,
    TorqueModel,
)
from prsm_health.estimation.params import EstimatorParams

FloatArray = NDArray[np.float64]
Filter = Any  # filterpy filters carry no type information

#: Smallest variance kept on each state, relative to its initial variance.
VARIANCE_FLOOR_RATIO = 1e-12


def safe_sqrt(matrix: FloatArray) -> FloatArray:
    """Upper Cholesky factor of a symmetric matrix, repaired to positive definite if needed.

    filterpy's sigma points take U with U.T @ U = P (scipy's upper Cholesky). A matrix that
    lost positive definiteness to round-off has its eigenvalues clipped to a floor first.
    """
    symmetric = 0.5 * (matrix + matrix.T)
    try:
        return np.asarray(np.linalg.cholesky(symmetric).T, dtype=np.float64)
    except np.linalg.LinAlgError:
        return np.asarray(np.linalg.cholesky(repair_covariance(symmetric)).T, dtype=np.float64)


#: Smallest eigenvalue kept in a covariance's correlation matrix (its shape, free of units).
CORRELATION_FLOOR = 1e-9


def repair_covariance(matrix: FloatArray, floor: FloatArray | None = None) -> FloatArray:
    """Symmetric positive definite version of ``matrix``.

    The states have very different units (N, N/s^2, relative ripple), so definiteness is
    judged and repaired on the correlation matrix D^-1/2 P D^-1/2: its eigenvalues are clipped
    to CORRELATION_FLOOR, and the variances to ``floor``.
    """
    symmetric = 0.5 * (matrix + matrix.T)
    variances = np.abs(np.diagonal(symmetric))
    if floor is not None:
        variances = np.maximum(variances, floor)
    variances = np.maximum(variances, 1e-300)
    scale = np.sqrt(variances)
    correlation = symmetric / np.outer(scale, scale)
    np.fill_diagonal(correlation, 1.0)
    values, vectors = np.linalg.eigh(correlation)
    values = np.maximum(values, CORRELATION_FLOOR)
    repaired = (vectors * values) @ vectors.T
    return np.asarray(repaired * np.outer(scale, scale), dtype=np.float64)


@dataclass(frozen=True)
class StepResult:
    """What one block did to the hypotheses.

    predictions: per active hypothesis, the model's prediction at its updated state.
    nis: normalised innovation squared per active hypothesis (before the update).
    gated: no hypothesis explained the block; it was not used.
    """

    predictions: dict[int, Prediction]
    nis: dict[int, float]
    gated: bool


class JamHypotheses:
    """The IMM bank (see the module docstring)."""

    def __init__(self, params: EstimatorParams, model: TorqueModel) -> None:
        self._params = params
        self._model = model
        self._dim = model.dim
        self.n_rollers = model.n_rollers
        self._rate_per_s = params.model.jam_rate_per_h / 3600.0
        self._prune = params.fidelity.prune_hypotheses
        rated = params.rated_load_n
        initial = np.zeros(self._dim)
        initial[LOAD] = rated**2
        initial[LOAD_RATE] = rated**2  # the full load within a second
        initial[LOAD_ACCELERATION] = (10.0 * rated) ** 2  # ... or within a third of a second
        self._ripple = model.ripple
        if self._ripple:
            initial[RIPPLE_COS:] = params.model.ripple_prior_std**2
        self._initial_var = initial
        self._floor = initial * VARIANCE_FLOOR_RATIO
        self._jump_cov = np.zeros((self._dim, self._dim))
        if self._ripple:
            self._jump_cov[RIPPLE_COS:, RIPPLE_COS:] = np.eye(2) * params.model.ripple_prior_std**2
        start = params.model.initial_jammed_rollers
        self.filters: dict[int, Filter] = {}
        self.log_prob: dict[int, float] = {}
        self._onset_weight: dict[int, float] = {}
        counts = [start] if self._prune else list(range(self.n_rollers + 1))
        for k in counts:
            self.filters[k] = self._new_filter(np.zeros(self._dim), np.diag(initial))
            self.log_prob[k] = 0.0 if k == start else -math.inf

    # --- filters ------------------------------------------------------------------------
    def _new_filter(self, x: FloatArray, p: FloatArray) -> Filter:
        if self._params.fidelity.filter == "ukf":
            points = MerweScaledSigmaPoints(
                self._dim, alpha=0.5, beta=2.0, kappa=0.0, sqrt_method=safe_sqrt
            )
            kf = UnscentedKalmanFilter(
                self._dim, 1, 1.0, hx=None, fx=_transition_apply, points=points
            )
        else:
            kf = ExtendedKalmanFilter(self._dim, 1)
        kf.x = x.copy()
        kf.P = p.copy()
        return kf

    def _process(self, jammed: int, dt: float, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Transition and process noise over dt from state x: the load as a white-jerk
        (constant acceleration) process; the ripple (only when jammed) as a random walk,
        widened by its prior size times the relative change of its load scale
        (:meth:`TorqueModel.ripple_drift`)."""
        transition = np.eye(self._dim)
        transition[LOAD, LOAD_RATE] = transition[LOAD_RATE, LOAD_ACCELERATION] = dt
        transition[LOAD, LOAD_ACCELERATION] = dt**2 / 2.0
        q = self._params.model.load_jerk_psd_n2_per_s5
        noise = np.zeros((self._dim, self._dim))
        noise[:LOAD_STATES, :LOAD_STATES] = q * np.array(
            [
                [dt**5 / 20.0, dt**4 / 8.0, dt**3 / 6.0],
                [dt**4 / 8.0, dt**3 / 3.0, dt**2 / 2.0],
                [dt**3 / 6.0, dt**2 / 2.0, dt],
            ]
        )
        if self._ripple and jammed:
            walk = self._params.model.ripple_random_walk_per_sqrt_s
            drift = self._model.ripple_drift(x, dt) * self._params.model.ripple_prior_std
            noise[RIPPLE_COS:, RIPPLE_COS:] = np.eye(2) * (walk**2 * dt + drift**2)
        return transition, noise

    # --- the IMM step -------------------------------------------------------------------
    def probabilities(self) -> FloatArray:
        """Probability of each jam count 0..N (zeros for pruned counts), summing to 1."""
        probs = np.zeros(self.n_rollers + 1)
        for k, value in self.log_prob.items():
            probs[k] = math.exp(value)
        return np.asarray(probs / probs.sum(), dtype=np.float64)

    def _mix(self, dt: float) -> None:
        """IMM mixing over one block (step 1), activating the next jam count if pruned."""
        p_jump = -math.expm1(-self._rate_per_s * dt)
        log_stay, log_jump = math.log1p(-p_jump), math.log(p_jump) if p_jump > 0 else -math.inf
        targets = sorted(self.filters)
        top = targets[-1]
        if top < self.n_rollers and top + 1 not in self.filters:
            targets.append(top + 1)
        mixed: dict[int, tuple[FloatArray, FloatArray, float]] = {}
        self._onset_weight = {}
        for j in targets:
            sources = []
            if j in self.filters:
                stay = self.log_prob[j] + (log_stay if j < self.n_rollers else 0.0)
                sources.append((stay, self.filters[j], 0))
            if j - 1 in self.filters:
                sources.append((self.log_prob[j - 1] + log_jump, self.filters[j - 1], 1))
            logs = np.array([s[0] for s in sources])
            total = float(np.logaddexp.reduce(logs)) if len(logs) else -math.inf
            if not math.isfinite(total):  # no probability flows here: keep the state
                kf = self.filters.get(j) or sources[0][1]
                mixed[j] = (kf.x.copy(), kf.P.copy(), -math.inf)
                continue
            weights = np.exp(logs - total)
            self._onset_weight[j] = sum(
                float(w) for w, s in zip(weights, sources, strict=True) if s[2]
            )
            x0 = sum(w * s[1].x for w, s in zip(weights, sources, strict=True))
            p0 = np.zeros((self._dim, self._dim))
            for w, (_, kf, jump) in zip(weights, sources, strict=True):
                d = kf.x - x0
                p0 += w * (kf.P + np.outer(d, d) + jump * self._jump_cov)
            mixed[j] = (np.asarray(x0, dtype=np.float64), p0, total)
        for j, (x0, p0, total) in mixed.items():
            if j not in self.filters:
                self.filters[j] = self._new_filter(x0, p0)
            else:
                self.filters[j].x, self.filters[j].P = x0, p0
            self.log_prob[j] = total

    def step(self, block: Block, *, evidence: bool = True) -> StepResult:
        """Mix, predict, update and reweight for one block (see the module docstring).

        ``evidence=False``: the filters update but the probabilities are not reweighted
        (the caller knows the block cannot tell jams from load changes).
        """
        dt = block.duration_s
        self._mix(dt)
        predictions: dict[int, Prediction] = {}
        nis: dict[int, float] = {}
        log_likelihood: dict[int, float] = {}
        z = np.array([block.motor_torque_nm])
        for k, kf in self.filters.items():
            transition, noise = self._process(k, dt, kf.x)
            if isinstance(kf, UnscentedKalmanFilter):
                kf.Q = noise
                kf.predict(dt=dt, fx=_transition_apply, transition=transition)
            else:
                kf.F, kf.Q = transition, noise
                kf.predict()
            onset = self._onset_weight.get(k, 0.0)
            mean, jacobian, variance = self._measurement(kf.x, block, k, onset)
            if isinstance(kf, UnscentedKalmanFilter):
                kf.update(z, R=np.array([[variance]]), hx=self._hx(block, k, onset))
            else:
                kf.update(
                    z,
                    HJacobian=_constant(jacobian[None, :]),
                    Hx=_constant(np.array([mean])),
                    R=np.array([[variance]]),
                )
            innovation = float(kf.y[0])
            spread = float(kf.S[0, 0])
            nis[k] = innovation**2 / spread
            log_likelihood[k] = -0.5 * (nis[k] + math.log(2.0 * math.pi * spread))
        gated = min(nis.values()) > self._params.filter.gate_nis
        for k, kf in self.filters.items():
            if gated:  # no hypothesis explains the block: keep the predicted states
                kf.x, kf.P = kf.x_prior.copy(), kf.P_prior.copy()
            kf.P = self._safe_covariance(kf.P)
            predictions[k] = self._model.predict(kf.x, block, k)
        if evidence and block.direction and not gated:
            for k in self.filters:
                self.log_prob[k] += log_likelihood[k]
        self._normalise()
        if self._prune:
            self._drop_unlikely()
        return StepResult(predictions=predictions, nis=nis, gated=gated)

    def _measurement(
        self, x: FloatArray, block: Block, jammed: int, onset: float
    ) -> tuple[float, FloatArray, float]:
        """Predicted torque, its Jacobian and variance for hypothesis ``jammed``.

        ``onset`` is the share of the hypothesis' probability that arrives by a jam in this
        block. Such a jam starts at a uniformly random instant inside the block, so the block
        mean lies between the two counts' torques: with D the difference, the prediction
        moves by -onset D / 2 and the variance grows by onset D^2 / 12 plus the spread of the
        two-part mixture onset (1 - onset) D^2 / 4. Without this, the block in which a jam
        starts would be explained by the new hypothesis' ripple states and corrupt them.
        """
        prediction = self._model.predict(x, block, jammed)
        if onset <= 0.0:
            return prediction.motor_torque_nm, prediction.jacobian, prediction.variance_nm2
        before = self._model.predict(x, block, jammed - 1)
        step = prediction.motor_torque_nm - before.motor_torque_nm
        mean = prediction.motor_torque_nm - 0.5 * onset * step
        jacobian = prediction.jacobian - 0.5 * onset * (prediction.jacobian - before.jacobian)
        variance = prediction.variance_nm2 + step**2 * (onset / 12.0 + onset * (1.0 - onset) / 4.0)
        return mean, jacobian, variance

    def _hx(self, block: Block, jammed: int, onset: float) -> Any:
        def hx(x: FloatArray) -> FloatArray:
            return np.array([self._measurement(x, block, jammed, onset)[0]])

        return hx

    def _safe_covariance(self, p: FloatArray) -> FloatArray:
        """Symmetric, variances at least the floor, correlation matrix positive definite."""
        p = 0.5 * (p + p.T)
        diagonal = np.diagonal(p)
        if np.any(diagonal < self._floor):
            p = p + np.diag(np.maximum(self._floor - diagonal, 0.0))
        scale = np.sqrt(np.diagonal(p))
        try:
            root = np.linalg.cholesky(p / np.outer(scale, scale))
            if float(np.diagonal(root).min()) ** 2 < CORRELATION_FLOOR:
                raise np.linalg.LinAlgError("nearly singular")
        except np.linalg.LinAlgError:
            p = repair_covariance(p, self._floor)
        return p

    def _normalise(self) -> None:
        total = float(np.logaddexp.reduce(list(self.log_prob.values())))
        for k in self.log_prob:
            self.log_prob[k] -= total

    def _drop_unlikely(self) -> None:
        """Prune hypotheses below the probability floor (never the most likely one)."""
        floor = math.log(max(self._params.filter.min_hypothesis_probability, 1e-300))
        best = max(self.log_prob, key=self.log_prob.__getitem__)
        for k in [k for k, value in self.log_prob.items() if value < floor and k != best]:
            del self.filters[k], self.log_prob[k]
        self._normalise()

    def restore(self, states: dict[int, tuple[FloatArray, FloatArray, float]]) -> None:
        """Replace the hypotheses by saved ones: count -> (x, P, log probability)."""
        self.filters = {
            k: self._new_filter(x, self._safe_covariance(p)) for k, (x, p, _) in states.items()
        }
        self.log_prob = {k: log_probability for k, (_, _, log_probability) in states.items()}
        self._normalise()

    def reinitialise_load(self, *, keep_load: bool = False) -> None:
        """Forget the load's derivatives, and unless ``keep_load`` the load too (after a time
        reset or a divergence; after a hole in the data, where the load may have moved on)."""
        forget = range(LOAD + 1 if keep_load else LOAD, LOAD_STATES)
        for kf in self.filters.values():
            x, p = kf.x.copy(), kf.P.copy()
            for i in forget:
                if i != LOAD:
                    x[i] = 0.0
                p[i, :] = 0.0
                p[:, i] = 0.0
                p[i, i] = self._initial_var[i]
            kf.x, kf.P = x, p


def _constant(value: FloatArray) -> Any:
    def function(_x: FloatArray) -> FloatArray:
        return value

    return function


def _transition_apply(x: FloatArray, dt: float, transition: FloatArray | None = None) -> FloatArray:
    """Process function of the UKF: x -> F x (the same linear model as the EKF's)."""
    if transition is None:
        return x
    return np.asarray(transition @ x, dtype=np.float64)
