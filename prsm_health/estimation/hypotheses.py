"""Jam-count hypotheses: a multiple-model filter over filterpy Kalman filters.

Hypothesis k says "k rollers are jammed"; each has its own filter over the continuous state
(load and its derivatives, ripple) and a probability. Jams only ever increase, with a prior
probability p = 1 - exp(-rate dt) per block, dt its duration but at most
``LONGEST_PREDICTION_S``. One step per block:

1. merging (the IMM mixing of Blom and Bar-Shalom, filterpy's ``IMMEstimator``): for each
   count k, the established hypotheses k (probability times 1 - p: no new jam) and the
   *fresh* hypotheses k of the previous block (a jam that started then, and has been tested
   by that block's likelihood) become Gaussians by moment matching: one for those whose
   loads agree within ``filter.merge_distance_sigmas``, at most
   ``filter.components_per_count`` per count (see below); then from every established k a
   fresh hypothesis k + 1 is born: the state of k (the load does not change when a roller
   seizes) plus the covariance of a new ripple of unknown phase (the ripple of
   ``model.ripple_prior_radial_n``, measurement.TorqueModel.ripple_relative, squared on c and
   s), with probability times p;
2. each filter predicts over dt and updates (filterpy ``ExtendedKalmanFilter`` or
   ``UnscentedKalmanFilter``; Joseph-form covariance update in the EKF). A fresh hypothesis
   predicts the block in which its jam starts at a uniformly random instant
   (:meth:`JamHypotheses._measurement`). While a stroke starts, an established hypothesis
   whose ripple phase has been and is known is updated with its ripple in polar coordinates
   (:mod:`prsm_health.estimation.phasor`: the phase keeps its uncertainty when the amplitude
   shrinks as the load builds up);
3. probabilities times the measurement likelihood N(y; 0, S). At standstill the likelihoods
   are not used: the stiction band carries no evidence about jams.

Why fresh hypotheses are merged one block late: merged at once (plain IMM), the state born
from count k would be averaged into hypothesis k + 1 every block with about the weight of
k + 1 itself while k + 1 is still improbable. When a jam happened unseen (at standstill), the
load of count k is biased by the jam's torque and would keep pulling k + 1 off, so that k + 1
could never gather the ripple's evidence. Tested by one block's likelihood first, a fresh
hypothesis that did not happen carries almost no weight into the merge.

Why a count may hold two Gaussians: "k + 1 jammed since the last standstill" (born there, its
load right) and "k + 1 jammed from this block on" (born from k, with k's load, which is biased
by the unseen jam's torque) are both count k + 1 but lie tens of standard deviations apart.
Moment-matched into one, the newborn (with the prior of a jam per block, about e^-18) pulled
the older one towards k's load as soon as the older one's probability fell below it, which the
ripple's extra variance makes happen while a stroke starts: the hypothesis that was right was
averaged away before the ripple could show it.

Why pruning has two floors: a fresh hypothesis below ``filter.min_hypothesis_probability``
(1e-9) is dropped, an established one only below ``filter.min_established_probability``
(1e-13). Dropping a fresh one loses nothing: the same jam is born again at the next block with
the same prior. An established one carries its history: after a jam at standstill, "k + 1
since the standstill" has the load that is right, and while the next stroke starts it loses a
few nats to k, whose load can follow the new ripple, and in a slow stroke at a small radial load
some tenths of a nat a block for seconds; dropped there, it can only come back as a newborn
with k's load, which is biased by the jam. The established floor alone (both at 1e-12)
keeps every fresh one that lost fewer than ten nats and with it a second Gaussian per count
most of the time, 30-45 % more time per sample; with the fresh floor where it was, the same
jams are found sooner at a few per cent (docs/estimation.md, pruning).

Why some jams are not born: a fresh hypothesis whose prior (its parent's probability times
that of a jam) lies below the established floor is not born when pruning. To be kept it would
have to gain more than ln(1e-9/1e-13) = 9.2 nats over the others in its one block. In steady
motion most such births come from the count above the likeliest one, which the newborns keep
at about 1e-9; their children start near 1e-17 and were dropped after their block. Not born,
they cost nothing (sudden-jam's estimator 14 % faster). Born at the fresh floor instead, a
held-out run lost a second jam (docs/estimation.md, pruning).

Why a load bound: with three or more of the downhole preset's ten rollers jammed the screw
self-locks (its friction per newton exceeds the load arm), and an assisting load explains the
torque of a smaller resisting one: a count one too high at an assisting load 5-6 times the
true one. After a short stop (supports of 0.3-0.5 s instead of the scenes' 2 s) such a
hypothesis, at 88-125 kN against a true 16-22 kN, outweighed the true count within seconds
(a false jam, 29-36 % load RMSE; docs/performance.md, "Motion and loads beyond the downhole
scenes"). Loads beyond ``model.plausible_load_factor`` times the preset's largest paper load
do not occur, so a hypothesis whose load lies more than PLAUSIBLE_LOAD_SIGMAS standard
deviations beyond that is dropped, as long as another lies within: an actuator that is
really loaded beyond it keeps every hypothesis (and its diagnostics say it is overloaded).

What filterpy's ``IMMEstimator`` does not do and this does: the fresh hypotheses above,
the load bound, pruning (jams never decrease, so a count that falls below its floor cannot
come back except by a new birth), gating (a block that no hypothesis explains is not used),
and numerical repair of the covariances (symmetrised, variance floors, positive definite).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
from numpy.typing import NDArray
from scipy.linalg.lapack import dpotrf

from prsm_health.estimation.inputs import Block
from prsm_health.estimation.measurement import (
    LOAD,
    LOAD_ACCELERATION,
    LOAD_RATE,
    LOAD_STATES,
    RIPPLE,
    Prediction,
    TorqueModel,
)
from prsm_health.estimation.params import EstimatorParams
from prsm_health.estimation.phasor import PolarPhasor, polar_about
from prsm_health.estimation.snapshot import SavedHypothesis

FloatArray = NDArray[np.float64]
Filter = Any  # filterpy filters carry no type information

#: Hypotheses less probable than exp(this) reuse their prediction from before the update.
NEGLIGIBLE_LOG_PROBABILITY = math.log(1e-6)

#: Longest prediction of the filters [s]. Blocks after a longer silence follow a re-acquisition
#: of the load (the estimator forgets its derivatives after HOLE_BLOCKS blocks of silence), and
#: from the initial derivative variances one second already spreads the load over five times
#: its rated value: predicting further adds no honesty, only a near rank-one covariance (load,
#: rate and acceleration correlated as 1, dt, dt^2/2) whose innovation variance loses its digits.
#: The jam prior of a block counts the same time: jams are a hazard of operation, and a jam
#: that happened during a silence shows in the data after it; a sensor clock jumping by years
#: must not declare a jam.
LONGEST_PREDICTION_S = 1.0

#: An EKF update that moves the load by more than this share of the load scale is checked
#: for linearisation error, and iterated if the model misses the measurement at the updated
#: state by more than ITERATION_SIGMAS of the measurement noise (JamHypotheses._ekf_update).
LARGE_UPDATE_RATIO = 0.02
ITERATION_SIGMAS = 3.0
MAX_ITERATIONS = 3
#: A standstill update is repeated with its noise evaluated at the updated load until the
#: noise changes by less than this fraction (_standstill_update).
BAND_VARIANCE_TOLERANCE = 0.1


#: A hypothesis whose load lies more than this many of its standard deviations beyond the
#: plausible bound (model.plausible_load_factor) is dropped while another lies within it.
PLAUSIBLE_LOAD_SIGMAS = 3.0

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


def ripple_axis(
    ripple: FloatArray, axis: FloatArray | None, *, moving: bool, known: bool
) -> FloatArray | None:
    """The axis u = r / |r| the ripple phasor r = (c, s) walks along (:func:`ripple_walk`), or
    None while its phase has never been known.

    A jammed roller's ripple is the first carrier harmonic of its sliding torque: its amplitude
    follows the radial load (0.53 N m per kN on dong2022-downhole, whatever the axial load), its
    phase is set by where the jammed rollers sit on the carrier and does not change
    (docs/estimation.md). ``known``: the phase is known (:func:`phase_known`); it is learned in
    motion only. The axis is refreshed while the phase is known and kept when it no longer is:
    the amplitude may shrink through zero with the radial load, and must not turn the phase on
    the way (a second jammed roller does turn it).
    """
    if moving and known:
        c, s = float(ripple[0]), float(ripple[1])
        return np.array([c, s]) / math.sqrt(c * c + s * s)
    return axis


def phase_known(ripple: FloatArray, covariance: FloatArray, phase_known_rad: float) -> bool:
    """Whether the phase of the ripple phasor r = (c, s) with covariance ``covariance`` is
    known: its standard deviation sqrt(v' P v) / |r|^2, v = (-s, c) the direction across r,
    is below ``phase_known_rad`` (a phasor of length zero has no phase)."""
    c, s = float(ripple[0]), float(ripple[1])
    amplitude2 = c * c + s * s
    (pcc, pcs), (psc, pss) = covariance.tolist()
    across_var = max(s * s * pcc - c * s * (pcs + psc) + c * c * pss, 0.0)
    # Compared as standard deviations: squaring amplitude2 could overflow.
    return amplitude2 > 0.0 and math.sqrt(across_var) < phase_known_rad * amplitude2


def ripple_walk(
    axis: FloatArray | None, *, dt: float, along_per_sqrt_s: float, across_per_sqrt_s: float
) -> FloatArray:
    """Process noise of the ripple phasor over ``dt`` (2 x 2): once its phase is known (``axis``
    u, :func:`ripple_axis`) the phasor walks along its axis and hardly across it,

        Q = dt (along^2 u u' + across^2 (I - u u')),

    before that (``axis`` None) at ``along_per_sqrt_s`` in every direction.
    """
    along2 = along_per_sqrt_s**2 * dt
    if axis is None:
        return np.array([[along2, 0.0], [0.0, along2]])
    # dt (along^2 u u' + across^2 (I - u u')) = across2 I + (along2 - across2) u u'
    across2 = across_per_sqrt_s**2 * dt
    ux, uy = axis.tolist()
    extra = along2 - across2
    off_diagonal = extra * ux * uy
    return np.array(
        [[across2 + extra * ux * ux, off_diagonal], [off_diagonal, across2 + extra * uy * uy]]
    )


@dataclass
class Hypothesis:
    """One hypothesis: the jam count, its filter, its log probability, whether it is fresh
    (the jam started in the current block), and the axis its ripple phasor walks along once
    its phase is known (:func:`ripple_axis`; None before)."""

    count: int
    filter: Filter
    log_prob: float
    fresh: bool = False
    ripple_axis: FloatArray | None = None


@dataclass(frozen=True)
class StepResult:
    """What one block did to the hypotheses (lists in the order of ``hypotheses`` after it).

    predictions: the model's prediction at each hypothesis' updated state. nis: normalised
    innovation squared of each (before the update). gated: no hypothesis explained the
    block; it was not used.
    """

    predictions: list[Prediction]
    nis: list[float]
    gated: bool


class JamHypotheses:
    """The multiple-model bank (see the module docstring)."""

    def __init__(self, params: EstimatorParams, model: TorqueModel) -> None:
        self._params = params
        self._model = model
        self._dim = model.dim
        self.n_rollers = model.n_rollers
        self._rate_per_s = params.model.jam_rate_per_h / 3600.0
        self._prune = params.fidelity.prune_hypotheses
        self._established_floor = math.log(max(params.filter.min_established_probability, 1e-300))
        self._fresh_floor = math.log(max(params.filter.min_hypothesis_probability, 1e-300))
        scale = params.load_scale_n
        self._large_update_n = LARGE_UPDATE_RATIO * scale
        self._plausible_load_n = params.model.plausible_load_factor * scale  # 0: no bound
        initial = np.zeros(self._dim)
        initial[LOAD] = scale**2
        initial[LOAD_RATE] = scale**2  # the full load within a second
        initial[LOAD_ACCELERATION] = (10.0 * scale) ** 2  # ... or within a third of a second
        self._ripple = model.ripple
        self._ekf = params.fidelity.filter != "ukf"
        ripple_prior_var = model.ripple_relative(params.model.ripple_prior_radial_n) ** 2
        self._ripple_along_per_sqrt_s = model.ripple_relative(
            params.model.ripple_walk_radial_n_per_sqrt_s
        )
        self._ripple_across_per_sqrt_s = model.ripple_relative(
            params.model.ripple_phase_walk_radial_n_per_sqrt_s
        )
        if self._ripple:
            initial[RIPPLE] = ripple_prior_var
        self._initial_var = initial
        self._floor = initial * VARIANCE_FLOOR_RATIO
        self._jump_cov = np.zeros((self._dim, self._dim))
        if self._ripple:
            self._jump_cov[RIPPLE, RIPPLE] = np.eye(2) * ripple_prior_var
        self._spare_filters: list[Filter] = []
        self._predicted: dict[tuple[bytes, int], Prediction] = {}
        self._process_cache: tuple[object, tuple[FloatArray, FloatArray]] = (
            None,
            (initial, initial),
        )
        self.hypotheses: list[Hypothesis] = []
        #: log p(y) of the blocks that weighed the counts so far: the sum of each such block's
        #: log sum_k P(k) N(y; h_k, S_k) (what the probabilities are normalised by).
        self.log_evidence = 0.0
        self._start(params.model.initial_jammed_rollers, np.zeros(self._dim), np.diag(initial))

    def _start(
        self, count: int, x: FloatArray, p: FloatArray, axis: FloatArray | None = None
    ) -> None:
        """Certainty of ``count`` jammed rollers at (x, P), its ripple walking along ``axis``:
        one hypothesis, or with pruning off every count, the others at probability zero."""
        self._spare_filters += [h.filter for h in self.hypotheses]
        counts = [count] if self._prune else list(range(self.n_rollers + 1))
        self.hypotheses = [
            Hypothesis(
                k,
                self._new_filter(x, p),
                0.0 if k == count else -math.inf,
                ripple_axis=axis if k == count else None,
            )
            for k in counts
        ]

    def reset_count(self, count: int) -> None:
        """Maintenance: ``count`` jammed rollers for certain. The load and its derivatives
        are the likeliest hypothesis' (maintenance does not move the load); the ripple is
        unknown again (prior variance, no phase): the rollers jammed now decide it."""
        best = self.most_likely().filter
        x, p = best.x.copy(), best.P.copy()
        if self._ripple:
            x[RIPPLE] = 0.0
            self._forget(p, RIPPLE)
        self._start(count, x, p)

    def assume_onset(self, count: int) -> None:
        """Diagnostics (estimation/evidence.py): ``count`` jammed rollers for certain from now
        on, as if the jams beyond the likeliest hypothesis' count had just been born: its
        state, with a new roller's ripple prior added per extra jammed roller (step 1 of the
        module docstring). Unlike :meth:`reset_count` the ripple learnt so far is kept."""
        best = self.most_likely()
        extra = count - best.count
        if not 0 <= extra <= self.n_rollers - best.count:
            raise ValueError(
                f"count: must be within {best.count}..{self.n_rollers} (jams only increase), "
                f"got {count}"
            )
        axis = best.ripple_axis if extra == 0 else None
        self._start(count, best.filter.x.copy(), best.filter.P + extra * self._jump_cov, axis)

    def _forget(self, p: FloatArray, states: slice) -> None:
        """Put ``states`` of the covariance ``p`` (in place) back at their initial variances,
        uncorrelated with the other states."""
        p[states, :] = 0.0
        p[:, states] = 0.0
        p[states, states] = np.diag(self._initial_var[states])

    # --- filters ------------------------------------------------------------------------
    def _new_filter(self, x: FloatArray, p: FloatArray) -> Filter:
        """A filter at (x, P); filters of merged-away hypotheses are reused."""
        if self._spare_filters:
            kf = self._spare_filters.pop()
            kf.x, kf.P = x.copy(), p.copy()
            return kf
        if self._params.fidelity.filter == "ukf":
            # alpha = 1, kappa = 0: lambda = alpha^2 (n + kappa) - n = 0, so the centre point's
            # mean weight is 0 and every other's 1/2n, none negative, and the points lie at
            # sqrt(n) standard deviations. At alpha = 0.5 the centre's mean weight was -3
            # (covariance weight -0.25): where the points straddle the friction's kink at zero
            # load, the predicted torque was an extrapolation (a stroke end of two-jam-10: NIS
            # 38, the load 507 N off, then a false count 3 and 90.9 kN off; docs/performance.md).
            points = MerweScaledSigmaPoints(
                self._dim, alpha=1.0, beta=2.0, kappa=0.0, sqrt_method=safe_sqrt
            )
            kf = UnscentedKalmanFilter(
                self._dim, 1, 1.0, hx=None, fx=_transition_apply, points=points
            )
        else:
            kf = ExtendedKalmanFilter(self._dim, 1)
        kf.x = x.copy()
        kf.P = p.copy()
        return kf

    def _process(self, dt: float, jerk_psd: float) -> tuple[FloatArray, FloatArray]:
        """Transition and load process noise over dt: the load as a white-jerk (constant
        acceleration) process (cached: consecutive blocks share dt and psd). The ripple's noise
        is each jammed hypothesis' own (:meth:`_ripple_noise`)."""
        key = (dt, jerk_psd)
        if self._process_cache[0] != key:
            transition = np.eye(self._dim)
            transition[LOAD, LOAD_RATE] = transition[LOAD_RATE, LOAD_ACCELERATION] = dt
            transition[LOAD, LOAD_ACCELERATION] = dt**2 / 2.0
            noise = np.zeros((self._dim, self._dim))
            noise[:LOAD_STATES, :LOAD_STATES] = jerk_psd * np.array(
                [
                    [dt**5 / 20.0, dt**4 / 8.0, dt**3 / 6.0],
                    [dt**4 / 8.0, dt**3 / 3.0, dt**2 / 2.0],
                    [dt**3 / 6.0, dt**2 / 2.0, dt],
                ]
            )
            for matrix in (transition, noise):
                matrix.setflags(write=False)
            self._process_cache = (key, (transition, noise))
        return self._process_cache[1]

    def _ripple_noise(self, h: Hypothesis, load_noise: FloatArray, dt: float) -> FloatArray:
        """The process noise of a jammed hypothesis: the load's and its ripple's walk along the
        hypothesis' axis (:func:`ripple_walk`)."""
        noise = load_noise.copy()
        noise[RIPPLE, RIPPLE] = ripple_walk(
            h.ripple_axis,
            dt=dt,
            along_per_sqrt_s=self._ripple_along_per_sqrt_s,
            across_per_sqrt_s=self._ripple_across_per_sqrt_s,
        )
        return noise

    def _polar_noise(self, noise: FloatArray, dt: float) -> FloatArray:
        """The process noise with the ripple's in polar coordinates: the amplitude walks at
        ``model.ripple_walk_radial_n_per_sqrt_s``, the phase at
        ``model.ripple_phase_walk_rad_per_sqrt_s``."""
        polar = noise.copy()
        polar[RIPPLE, RIPPLE] = np.diag(
            [
                self._ripple_along_per_sqrt_s**2 * dt,
                self._params.model.ripple_phase_walk_rad_per_sqrt_s**2 * dt,
            ]
        )
        return polar

    # --- the step -----------------------------------------------------------------------
    def probabilities(self) -> FloatArray:
        """Probability of each jam count 0..N (zeros for pruned counts), summing to 1."""
        probs = np.zeros(self.n_rollers + 1)
        for h in self.hypotheses:
            probs[h.count] += math.exp(h.log_prob)
        return np.asarray(probs / probs.sum(), dtype=np.float64)

    def _merge(self, dt: float) -> None:
        """Step 1 of the module docstring: merge each count, then give birth to fresh jams."""
        if self._prune:
            self._drop_unlikely()
        expected_jams = self._rate_per_s * dt
        log_stay = -expected_jams  # exact: no 1 - p to round to 0 over a long block
        log_jump = math.log(-math.expm1(-expected_jams)) if expected_jams > 0.0 else -math.inf
        by_count: dict[int, list[Hypothesis]] = {}
        for h in self.hypotheses:
            by_count.setdefault(h.count, []).append(h)
        established = []
        for count in sorted(by_count):
            stay = log_stay if count < self.n_rollers else 0.0
            members = by_count[count]
            for h in members:
                h.log_prob += stay
            established += [self._moment_match(group) for group in self._groups(members)]
        # Not born below the established floor when pruning (the module docstring), nor with
        # probability zero (a ruled-out parent, or no jams at rate 0).
        lowest = self._established_floor if self._prune else -math.inf
        priors = [(h, h.log_prob - log_stay + log_jump) for h in established]
        fresh = [
            Hypothesis(
                h.count + 1,
                self._new_filter(h.filter.x, h.filter.P + self._jump_cov),
                prior,
                fresh=True,
            )
            for h, prior in priors
            if h.count < self.n_rollers and math.isfinite(prior) and prior >= lowest
        ]
        self.hypotheses = established + fresh

    def _groups(self, members: list[Hypothesis]) -> list[list[Hypothesis]]:
        """Members of one count in at most ``filter.components_per_count`` groups: each, most
        probable first, joins the group whose most probable member's load is nearest to its
        own if that is within ``filter.merge_distance_sigmas`` or there is no room for
        another group, else starts one."""
        limit = self._params.filter.components_per_count
        near = self._params.filter.merge_distance_sigmas**2
        groups: list[list[Hypothesis]] = []
        for h in sorted(members, key=lambda h: -h.log_prob):
            if groups:
                distance, nearest = min((_load_distance2(g[0], h), i) for i, g in enumerate(groups))
                if distance <= near or len(groups) >= limit:
                    groups[nearest].append(h)
                    continue
            groups.append([h])
        return groups

    def _moment_match(self, members: list[Hypothesis]) -> Hypothesis:
        """One Gaussian with the members' total probability and their mean and covariance,
        carried by the first member's filter (the most probable: :meth:`_groups` sorts them);
        the others' filters become spares."""
        kept = members[0]
        total = kept.log_prob
        if len(members) > 1:
            logs = np.array([h.log_prob for h in members])
            total = float(np.logaddexp.reduce(logs))
            if math.isfinite(total):
                weights = np.exp(logs - total)
                x0 = sum(w * h.filter.x for w, h in zip(weights, members, strict=True))
                p0 = np.zeros((self._dim, self._dim))
                for w, h in zip(weights, members, strict=True):
                    d = h.filter.x - x0
                    p0 += w * (h.filter.P + np.outer(d, d))
                kept.filter.x, kept.filter.P = np.asarray(x0, dtype=np.float64), p0
            self._spare_filters += [h.filter for h in members[1:]]
        kept.log_prob, kept.fresh = total, False
        return kept

    def step(
        self,
        block: Block,
        *,
        jerk_psd: float,
        evidence: bool = True,
        load_transition: bool = False,
    ) -> StepResult:
        """Merge, predict, update and reweight for one block (see the module docstring).

        ``jerk_psd``: the load model's jerk density for this block [N^2/s^5].
        ``load_transition``: a stroke starts (or the actuator stands): the EKF updates the ripple
        of a hypothesis whose phase has been known (its ripple axis is set) and is known now
        (:func:`phase_known`: about a phasor of uncertain phase a linearisation in polar
        coordinates does not hold) in polar coordinates (:mod:`prsm_health.estimation.phasor`,
        :meth:`_polar_noise`).
        ``evidence=False``: the filters update but the probabilities are not reweighted
        (the caller knows the block cannot tell jams from load changes).
        """
        dt = min(block.duration_s, LONGEST_PREDICTION_S)
        self._merge(dt)
        nis: list[float] = []
        log_likelihood: list[float] = []
        priors: list[Prediction] = []
        self._predicted = {}
        z = np.array([block.motor_torque_nm])
        polars: list[PolarPhasor | None] = []
        phase_known_rad = self._params.model.ripple_phase_known_rad
        for h in self.hypotheses:
            kf = h.filter
            transition, noise = self._process(dt, jerk_psd)
            polar = None
            if self._ripple and h.count:
                known = phase_known(kf.x[RIPPLE], kf.P[RIPPLE, RIPPLE], phase_known_rad)
                h.ripple_axis = ripple_axis(
                    kf.x[RIPPLE], h.ripple_axis, moving=bool(block.direction), known=known
                )
                if load_transition and h.ripple_axis is not None and self._ekf and known:
                    polar = polar_about(kf.x)
                if polar is None:
                    noise = self._ripple_noise(h, noise, dt)
                else:
                    kf.x, kf.P = polar.to_polar(kf.x, kf.P)
                    noise = self._polar_noise(noise, dt)
            polars.append(polar)
            if isinstance(kf, UnscentedKalmanFilter):
                kf.Q = noise
                kf.predict(dt=dt, fx=_transition_apply, transition=transition)
                # filterpy 1.4.5's update reuses the propagated sigma points, which miss the
                # process noise Q added after them (filterpy issues 172 and 180, fixed after
                # that release): drawn again from the prior they carry it.
                kf.sigmas_f = kf.points_fn.sigma_points(kf.x, kf.P)
            else:
                kf.F, kf.Q = transition, noise
                kf.predict()
            prior, mean, jacobian, variance = self._measurement(
                kf.x, block, h.count, h.fresh, polar
            )
            priors.append(prior)
            if isinstance(kf, UnscentedKalmanFilter):
                kf.update(z, R=np.array([[variance]]), hx=self._hx(block, h.count, h.fresh))
            else:
                self._ekf_update(kf, z, block, h, (mean, jacobian, variance), polar)
            innovation = float(kf.y[0])
            spread = float(kf.S[0, 0])
            nis.append(innovation**2 / spread)
            log_likelihood.append(-0.5 * (nis[-1] + math.log(2.0 * math.pi * spread)))
        gated = min(nis) > self._params.filter.gate_nis
        weighed = evidence and bool(block.direction) and not gated
        if weighed:
            for h, value in zip(self.hypotheses, log_likelihood, strict=True):
                h.log_prob += value
        total = self._normalise()
        if weighed:
            self.log_evidence += total
        predictions = []
        for h, prior, polar in zip(self.hypotheses, priors, polars, strict=True):
            kf = h.filter
            if gated:  # no hypothesis explains the block: keep the predicted states
                kf.x, kf.P = kf.x_prior.copy(), kf.P_prior.copy()
            if polar is not None:
                kf.x, kf.P = polar.to_cartesian(kf.x, kf.P)
            kf.P = self._safe_covariance(kf.P)
            # The outputs weigh each prediction by its probability: for a negligible one the
            # prediction before the update serves (it saves a model evaluation per block).
            significant = h.log_prob > NEGLIGIBLE_LOG_PROBABILITY and not gated
            predictions.append(self._predict(kf.x, block, h.count) if significant else prior)
        return StepResult(predictions=predictions, nis=nis, gated=gated)

    def _ekf_update(
        self,
        kf: Filter,
        z: FloatArray,
        block: Block,
        h: Hypothesis,
        linearised: tuple[float, FloatArray, float],
        polar: PolarPhasor | None,
    ) -> None:
        """EKF update from the prior, iterated (Gauss-Newton, the iterated EKF) when it moved
        the load by more than LARGE_UPDATE_RATIO of the load scale and the model misses the
        measurement at the updated state by more than ITERATION_SIGMAS of its noise.

        Such an update follows a re-acquisition (after a hole in the data the prior stays at
        the last load while the torque says another): linearised tens of kN away, a single
        update lands hundreds of newtons off with a standard deviation of tens. Each iteration
        re-linearises at the latest state x_i and updates the prior with the measurement
        prediction h(x_i) + H_i (x_prior - x_i), at most MAX_ITERATIONS times.
        """
        if block.direction == 0:
            _standstill_update(
                kf, z, linearised, lambda x: self._measurement(x, block, h.count, h.fresh, polar)
            )
            return
        x_prior = kf.x_prior  # filterpy's copy of the predicted state (P_prior likewise)
        predicted, jacobian, variance = linearised
        for iteration in range(MAX_ITERATIONS + 1):
            _update_prior(kf, z, (predicted, jacobian, variance), again=iteration > 0)
            moved = abs(float(kf.x[LOAD] - x_prior[LOAD]))
            if iteration == MAX_ITERATIONS or moved <= self._large_update_n:
                return
            _, mean, jacobian, variance = self._measurement(kf.x, block, h.count, h.fresh, polar)
            if (float(z[0]) - mean) ** 2 <= ITERATION_SIGMAS**2 * variance:
                return
            predicted = mean + float(jacobian @ (x_prior - kf.x))

    def _measurement(
        self,
        x: FloatArray,
        block: Block,
        jammed: int,
        fresh: bool,
        polar: PolarPhasor | None = None,
    ) -> tuple[Prediction, float, FloatArray, float]:
        """The model's prediction for ``jammed`` rollers, and the measurement's mean, Jacobian
        and variance for the hypothesis.

        A fresh hypothesis' jam starts at a uniformly random instant inside the block, so the
        block mean lies between the two counts' torques: with D their difference, the mean is
        moved by -D / 2 and the variance grows by D^2 / 12. Without this, the block in which
        a jam starts would be explained by the new hypothesis' ripple states and corrupt them.

        ``polar``: ``x`` has its ripple in these polar coordinates, and so has the Jacobian.
        """
        cartesian = x if polar is None else polar.cartesian_state(x)
        prediction = self._predict(cartesian, block, jammed)
        mean, jacobian, variance = (
            prediction.motor_torque_nm,
            prediction.jacobian,
            prediction.variance_nm2,
        )
        if fresh:
            before = self._predict(cartesian, block, jammed - 1)
            step = prediction.motor_torque_nm - before.motor_torque_nm
            mean -= 0.5 * step
            jacobian = 0.5 * (jacobian + before.jacobian)
            variance += step**2 / 12.0
        if polar is not None:
            jacobian = polar.polar_jacobian(x, jacobian)
        return prediction, mean, jacobian, variance

    def _predict(self, x: FloatArray, block: Block, jammed: int) -> Prediction:
        """The model's prediction, computed once per state and count in a block: a fresh
        hypothesis predicts from its parent's state, and its jam starting inside the block
        needs the parent's count's prediction there too (:meth:`_measurement`)."""
        key = (x.tobytes(), jammed)
        prediction = self._predicted.get(key)
        if prediction is None:
            prediction = self._predicted[key] = self._model.predict(x, block, jammed)
        return prediction

    def _hx(self, block: Block, jammed: int, fresh: bool) -> Any:
        def hx(x: FloatArray) -> FloatArray:
            return np.array([self._measurement(x, block, jammed, fresh)[1]])

        return hx

    def _safe_covariance(self, p: FloatArray) -> FloatArray:
        """Symmetric, variances at least the floor, correlation matrix positive definite."""
        p = 0.5 * (p + p.T)
        diagonal = p.diagonal()
        if (diagonal < self._floor).any():
            p = p + np.diag(np.maximum(self._floor - diagonal, 0.0))
        scale = np.sqrt(p.diagonal())
        root, info = dpotrf(p / (scale[:, None] * scale), lower=1, clean=0)
        if info != 0 or float(root.diagonal().min()) ** 2 < CORRELATION_FLOOR:
            p = repair_covariance(p, self._floor)
        return p

    def _normalise(self) -> float:
        """Probabilities summing to 1; returns the log of what they summed to."""
        total = float(np.logaddexp.reduce([h.log_prob for h in self.hypotheses]))
        for h in self.hypotheses:
            h.log_prob -= total
        return total

    def _drop_unlikely(self) -> None:
        """Prune the hypotheses whose load is not plausible, while any is (see the module
        docstring), and then those below their probability floor (never the most likely one):
        a fresh one below ``filter.min_hypothesis_probability``, an established one below
        ``filter.min_established_probability``."""
        fresh_floor, established_floor = self._fresh_floor, self._established_floor
        candidates = [h for h in self.hypotheses if self._plausible(h)] or self.hypotheses
        best = max(candidates, key=lambda h: h.log_prob)
        kept = [
            h
            for h in candidates
            if h is best or h.log_prob >= (fresh_floor if h.fresh else established_floor)
        ]
        self._spare_filters += [h.filter for h in self.hypotheses if h not in kept]
        self.hypotheses = kept
        self._normalise()

    def _plausible(self, h: Hypothesis) -> bool:
        """Whether the load of ``h`` lies less than PLAUSIBLE_LOAD_SIGMAS of its standard
        deviations beyond the plausible bound (always when there is none)."""
        excess = abs(float(h.filter.x[LOAD])) - self._plausible_load_n
        return self._plausible_load_n == 0.0 or excess <= PLAUSIBLE_LOAD_SIGMAS * math.sqrt(
            float(h.filter.P[LOAD, LOAD])
        )

    def restore(self, states: list[SavedHypothesis]) -> None:
        """Replace the hypotheses by saved ones."""
        self.hypotheses = [
            Hypothesis(k, self._new_filter(x, self._safe_covariance(p)), log_prob, fresh, axis)
            for k, fresh, x, p, log_prob, axis in states
        ]
        self._normalise()

    def restart_filters(self, counts: list[tuple[int, float]]) -> None:
        """The jam counts with the log probabilities given (count, log probability; several
        of one count add up), each filtered afresh from the initial state, as at the start:
        a state restored for other drive-train or model parameters (HealthEstimator.restore).
        With pruning the counts of probability zero are left out, without it they stay."""
        log_probability = dict.fromkeys(range(self.n_rollers + 1), -math.inf)
        for count, log_prob in counts:
            log_probability[count] = float(np.logaddexp(log_probability[count], log_prob))
        self._spare_filters += [h.filter for h in self.hypotheses]
        x, p = np.zeros(self._dim), np.diag(self._initial_var)
        self.hypotheses = [
            Hypothesis(k, self._new_filter(x, p), log_prob)
            for k, log_prob in log_probability.items()
            if math.isfinite(log_prob) or not self._prune
        ]
        self._normalise()

    def reinitialise_load(self, *, keep_load: bool = False) -> None:
        """Forget the load's derivatives, and unless ``keep_load`` the load too (after a time
        reset or a divergence; after a hole in the data, where the load may have moved on).
        A forgotten load keeps its mean as the start of its re-acquisition, unless that lies
        beyond the divergence bound (EstimatorParams.diverged_load_n): then it starts from
        zero. A load or load standard deviation beyond that bound is never kept: after a
        restore (a hole) such a one came from a damaged state file, and the wear integrated
        at it was poisoned for good (4e74 um of precision loss, found by a review session)."""
        diverged = self._params.diverged_load_n
        for h in self.hypotheses:
            x, p = h.filter.x.copy(), h.filter.P.copy()
            keep = keep_load and abs(float(x[LOAD])) <= diverged and p[LOAD, LOAD] <= diverged**2
            if not keep and abs(float(x[LOAD])) > diverged:
                x[LOAD] = 0.0
            x[LOAD_RATE:LOAD_STATES] = 0.0
            self._forget(p, slice(LOAD_RATE if keep else LOAD, LOAD_STATES))
            h.filter.x, h.filter.P = x, p

    def most_likely(self) -> Hypothesis:
        """The hypothesis with the largest probability."""
        return max(self.hypotheses, key=lambda h: h.log_prob)


def _load_distance2(a: Hypothesis, b: Hypothesis) -> float:
    """Squared difference of two hypotheses' loads over the sum of their load variances."""
    difference = float(a.filter.x[LOAD] - b.filter.x[LOAD])
    return difference**2 / float(a.filter.P[LOAD, LOAD] + b.filter.P[LOAD, LOAD])


def _standstill_update(
    kf: Filter,
    z: FloatArray,
    linearised: tuple[float, FloatArray, float],
    measure: Callable[[FloatArray], tuple[Prediction, float, FloatArray, float]],
) -> None:
    """EKF update of a standstill block, iterated on its noise: the stiction band's share
    M_static(|F|)^2 / 3 (measurement.py) grows with the load. Evaluated at the predicted
    load, which after a stroke's end can be kN off with a standard deviation of tens of kN,
    it made a held torque look uninformative (a load held at zero read 0.1 +- 16 kN,
    errors up to 40 kN at standstill with two jammed rollers). So the noise is evaluated
    again at the updated load and the update repeated, until the noise changes by less
    than BAND_VARIANCE_TOLERANCE (at most MAX_ITERATIONS times; the measurement is linear
    in the load at standstill, its mean and Jacobian stay). Not where the count
    self-locks the screw at the updated load (Prediction.self_locking): any load held by
    the band then explains the torque, and a band evaluated at a small updated load would
    claim the load known. ``measure``: the hypothesis' measurement at a state
    (JamHypotheses._measurement). The innovation and its variance (kf.y, kf.S: the NIS of the
    gate and the divergence test) stay the first update's, with the noise as predicted: an
    iteration changes the estimate, not how surprising the block was."""
    predicted, jacobian, variance = linearised
    _update_prior(kf, z, linearised)
    innovation = kf.y.copy(), kf.S.copy()
    for _ in range(MAX_ITERATIONS):
        at_result, _, _, noise = measure(kf.x)
        if at_result.self_locking or abs(noise - variance) <= BAND_VARIANCE_TOLERANCE * variance:
            break
        variance = noise
        _update_prior(kf, z, (predicted, jacobian, variance), again=True)
    kf.y, kf.S = innovation


def _update_prior(
    kf: Filter, z: FloatArray, linearised: tuple[float, FloatArray, float], *, again: bool = False
) -> None:
    """One EKF update of the predicted state by the measurement linearised as (prediction,
    Jacobian, variance); ``again``: the filter holds an earlier update's result, so it is put
    back to the prediction first (filterpy's x_prior, P_prior, which an update leaves as they
    are; the first update starts there already, with no copy in the hot path)."""
    predicted, jacobian, variance = linearised
    if again:
        kf.x, kf.P = kf.x_prior.copy(), kf.P_prior.copy()
    kf.update(
        z,
        HJacobian=_constant(jacobian[None, :]),
        Hx=_constant(np.array([predicted])),
        R=np.array([[variance]]),
    )


def _constant(value: FloatArray) -> Any:
    def function(_x: FloatArray) -> FloatArray:
        return value

    return function


def _transition_apply(x: FloatArray, dt: float, transition: FloatArray) -> FloatArray:
    """Process function of the UKF: x -> F x (the same linear model as the EKF's)."""
    return np.asarray(transition @ x, dtype=np.float64)
