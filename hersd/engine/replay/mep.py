"""Maximum-entropy-regularised prioritisation (MEP; Zhao, Sun & Tresp, ICML 2019).

MEP replays rare achieved-goal trajectories more often: a Bayesian Gaussian mixture is fit
to the stored trajectories, each flattened to a row of (T+1) * goal_dim numbers; an
episode's *rarity* is minus its log density; its sampling probability grows with the rank
of its rarity in the buffer. The sampled episodes are then relabelled as HER does, so MEP
combines with every relabel schedule and reward weighting.

What differs from the original code, and why (the quantities computed are the same):

- the mixture is fit on at most ``fit_subsample`` stored trajectories drawn uniformly,
  warm-started from the previous epoch's fit, instead of from scratch on the whole buffer
  (which the MEP paper reports slows training more than tenfold);
- rarities live in a per-slot array in buffer order: new episodes are scored when stored,
  and every stored episode is re-scored once per epoch after the fit, in one call;
- ranks run from 1 (the most common trajectory), not from 0, so the most common
  trajectory keeps a small non-zero probability instead of never being replayed.

The functions take everything they use as arguments (``fit_density`` updates the model it
is given); :class:`EpisodePrioritizer` holds the fitted model and the rarity array for the
training loop and its checkpoint. Fitting and scoring use one BLAS thread, whatever
``threads`` gives the run's torch work: runs of a sweep share the cores, and an
oversubscribed multi-threaded BLAS made a fit fifty times slower on a loaded 2-core
machine (docs/MEP.md).
"""

from __future__ import annotations

import warnings
from typing import Optional

import numpy as np
from scipy.stats import rankdata
from sklearn.exceptions import ConvergenceWarning
from sklearn.mixture import BayesianGaussianMixture
from threadpoolctl import threadpool_limits

from hersd.contract.config import MEPConfig


def trajectory_features(achieved: np.ndarray) -> np.ndarray:
    """Achieved goals (n, T+1, goal_dim) -> one float64 row per trajectory, (n, (T+1) * goal_dim)."""
    return achieved.reshape(achieved.shape[0], -1).astype(np.float64)


def new_density_model(cfg: MEPConfig, seed: int) -> BayesianGaussianMixture:
    """An unfitted mixture as in the MEP code (full covariances, Dirichlet-distribution weight
    prior), with ``warm_start`` so each later fit starts from the previous solution."""
    return BayesianGaussianMixture(n_components=cfg.n_components, max_iter=cfg.max_iter,
                                   weight_concentration_prior_type="dirichlet_distribution",
                                   warm_start=True, random_state=seed)


def fit_density(model: BayesianGaussianMixture, achieved: np.ndarray, fit_subsample: int,
                rng: np.random.Generator) -> BayesianGaussianMixture:
    """Fit ``model`` in place to at most ``fit_subsample`` of the trajectories achieved
    (n, T+1, goal_dim), drawn uniformly without replacement with ``rng``; returns it.

    Running out of EM iterations is expected on warm starts and not reported.
    """
    rows = achieved if achieved.shape[0] <= fit_subsample else \
        achieved[np.sort(rng.choice(achieved.shape[0], size=fit_subsample, replace=False))]
    with warnings.catch_warnings(), threadpool_limits(limits=1):
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(trajectory_features(rows))
    return model


def trajectory_rarity(model: BayesianGaussianMixture, achieved: np.ndarray) -> np.ndarray:
    """Rarity = -log density of each trajectory in achieved (n, T+1, goal_dim) -> (n,) float64.

    A non-finite density (a trajectory far outside the fitted data) counts as the rarest.
    """
    with threadpool_limits(limits=1):
        log_density = model.score_samples(trajectory_features(achieved))
    return np.nan_to_num(-log_density, nan=np.inf)


def rank_priorities(rarity: np.ndarray, temperature: float) -> np.ndarray:
    """Sampling probabilities (n,) from rarities (n,): p_i proportional to rank_i ** (1 / temperature).

    rank_i is the dense rank of rarity_i (1 = most common; equal rarities share a rank), so
    with n distinct rarities and temperature 1 the rarest episode is n times as likely as the
    most common; a higher temperature flattens the distribution towards uniform.
    """
    ranks = rankdata(rarity, method="dense").astype(np.float64)
    weights = ranks ** (1.0 / temperature)
    return weights / weights.sum()


def entropy(probs: np.ndarray) -> float:
    """Entropy in nats of a distribution probs (n,); log(n) when uniform."""
    positive = probs[probs > 0]
    return float(-(positive * np.log(positive)).sum())


class EpisodePrioritizer:
    """MEP state for one replay buffer: the density model and a rarity per buffer slot.

    ``rarity`` has shape (capacity,), indexed like the buffer's episode slots. Before the
    first fit :meth:`probs` returns None: the sampler then draws episodes uniformly.
    """

    def __init__(self, cfg: MEPConfig, capacity: int):
        self.cfg = cfg
        self.model: Optional[BayesianGaussianMixture] = None
        self.rarity = np.zeros(capacity, np.float64)

    @property
    def fitted(self) -> bool:
        return self.model is not None

    def fit(self, stored_achieved: np.ndarray, rng: np.random.Generator) -> None:
        """Refit on the stored trajectories (size, T+1, goal_dim) and re-score all of them.

        Fewer stored trajectories than mixture components: nothing happens (sampling stays
        as it was). ``rng`` picks the subsample and, on the first fit, the model's seed.
        """
        if stored_achieved.shape[0] < self.cfg.n_components:
            return
        if self.model is None:
            self.model = new_density_model(self.cfg, int(rng.integers(2 ** 31)))
        fit_density(self.model, stored_achieved, self.cfg.fit_subsample, rng)
        self.rarity[:stored_achieved.shape[0]] = trajectory_rarity(self.model, stored_achieved)

    def score_new(self, slots: np.ndarray, achieved: np.ndarray) -> None:
        """Score episodes just stored in ``slots`` (n,) from their achieved goals (n, T+1, goal_dim)
        with the current model (no-op before the first fit)."""
        if self.model is not None:
            self.rarity[slots] = trajectory_rarity(self.model, achieved)

    def probs(self, size: int) -> Optional[np.ndarray]:
        """Episode sampling probabilities (size,) over the first ``size`` slots; None before the first fit."""
        if self.model is None:
            return None
        return rank_priorities(self.rarity[:size], self.cfg.temperature)

    def entropy(self, size: int) -> float:
        """Entropy in nats of the distribution episodes are drawn from (uniform before the first fit)."""
        probs = self.probs(size)
        return float(np.log(size)) if probs is None else entropy(probs)

    def state_dict(self) -> dict:
        return {"model": self.model, "rarity": self.rarity.copy()}

    def load_state_dict(self, state: dict) -> None:
        self.model = state["model"]
        self.rarity[:] = state["rarity"]
