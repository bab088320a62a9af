"""How much the motor signals say about each jam onset, under the estimator's own model.

The filter bank decides a jam count from the likelihoods of its hypotheses, and its
approximations (pruning, merging, the one-block-late merge of fresh hypotheses) decide what
becomes of that evidence. This module measures the evidence itself, for a run whose true
onsets are known (the benchmark's): the log-likelihood ratio

    LLR_i = log p(y | the true counts) - log p(y | one jammed roller fewer from onset i on)

summed over the blocks that weigh the counts within ``window_s`` after onset i (or up to the
next onset, whichever comes first), each path run through :class:`HealthEstimator` with no
jams of its own (``model.jam_rate_per_h = 0``): a single hypothesis whose count changes only
where the path says, as a birth in the filter would change it
(:meth:`HealthEstimator.assume_jam_onset`). The log-likelihoods are the prediction-error
decomposition of the filter's model (:attr:`HealthEstimator.log_evidence`).

A positive LLR is evidence for the jam; against the prior odds of a jam (about -18 nats for a
40 ms block at the default rate) it says whether any filter of this model could identify it in
that window. A value near zero or below says that the data, as this model sees them, cannot
tell (docs/estimation.md, "Evidence for each onset").
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from prsm_health.estimation.estimator import HealthEstimator
from prsm_health.estimation.params import EstimatorParams
from prsm_health.signals import MotorSamples


def _log_evidence_at(
    params: EstimatorParams,
    samples: MotorSamples,
    onsets_s: Sequence[float],
    counts: Sequence[int],
    reads_s: Sequence[float],
) -> dict[float, float]:
    """The estimator's log evidence after the samples before each time of ``reads_s``, with
    the count set to ``counts[i]`` at ``onsets_s[i]`` (no other jams). The pending block is
    closed at every onset, whatever the count does there, so that paths that differ only in
    their counts see the same blocks."""
    estimator = HealthEstimator(params)
    last = max(reads_s)
    events = sorted(time_s for time_s in {*onsets_s, *reads_s} if time_s <= last)
    onset_count = dict(zip(onsets_s, counts, strict=True))
    found: dict[float, float] = {}
    begin = 0
    for time_s in events:
        end = int(np.searchsorted(samples.stamp_s, time_s))
        estimator.process(samples[begin:end])
        begin = end
        if time_s in onset_count:
            estimator.assume_jam_onset(onset_count[time_s])
        if time_s in reads_s:
            found[time_s] = estimator.log_evidence
    return found


def onset_evidence(
    params: EstimatorParams,
    samples: MotorSamples,
    onsets_s: Sequence[float],
    counts: Sequence[int],
    *,
    window_s: float,
) -> list[float]:
    """LLR_i of the module docstring [nats] for each onset (``onsets_s`` increasing, the true
    count from each on in ``counts``)."""
    if window_s <= 0.0:
        raise ValueError(f"window_s: must be > 0, got {window_s!r}")
    if len(onsets_s) != len(counts) or np.any(np.diff(onsets_s) <= 0.0):
        raise ValueError("onsets_s: one increasing time per count")
    told = dataclasses.replace(params, model=dataclasses.replace(params.model, jam_rate_per_h=0.0))
    ends = [min([onset + window_s, *onsets_s[i + 1 : i + 2]]) for i, onset in enumerate(onsets_s)]
    true_path = _log_evidence_at(told, samples, onsets_s, counts, [*onsets_s, *ends])
    evidence = []
    for i, (onset, end) in enumerate(zip(onsets_s, ends, strict=True)):
        fewer = [*counts[:i], counts[i] - 1, *counts[i + 1 :]]
        other = _log_evidence_at(told, samples, onsets_s, fewer, [onset, end])
        evidence.append((true_path[end] - true_path[onset]) - (other[end] - other[onset]))
    return evidence
