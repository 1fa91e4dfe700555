"""Losses of the latent dynamic adapter.

Paper eq. 1: max_{phi, psi} log p_{phi, psi}(s_drp_{t+1} | s_body_t, s_arm_t, p_arm_t), with the
decoder's output a diagonal Gaussian. We minimise the mean negative log-likelihood per sample in
standardised units (the target divided by its training std), so the loss does not depend on the
units of the roll and pitch rates; a constant predictor (the training mean and std) scores
`constant_nll`, the bar a useful adapter must clear on held-out data.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jp

_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)


def gaussian_nll(mean: jax.Array, log_std: jax.Array, target: jax.Array) -> jax.Array:
    """Eq. 1 negated: -log N(target; mean, diag(exp(log_std)^2)), summed over the last axis and
    averaged over the rest. Shapes (..., d)."""
    z = (target - mean) * jp.exp(-log_std)
    per_sample = jp.sum(0.5 * z**2 + log_std + _HALF_LOG_2PI, axis=-1)
    return jp.mean(per_sample)


def constant_nll(target: jax.Array) -> jax.Array:
    """The NLL of the constant predictor N(0, 1) on standardised targets (..., d): the score of
    predicting the training mean with the training std, whatever the input."""
    return gaussian_nll(jp.zeros_like(target), jp.zeros_like(target), target)
