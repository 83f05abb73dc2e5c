"""The Optuna internals of sweeps/search/optuna_private.py still behave as hersd-search expects: this fails when an
Optuna release renames or changes them."""

from __future__ import annotations

import optuna

from sweeps.search.optuna_private import fixed_params, seed_tpe


def _draws(sampler_seed: int, reseed: int | None) -> list[float]:
    sampler = optuna.samplers.TPESampler(seed=sampler_seed, n_startup_trials=2)
    study = optuna.create_study(sampler=sampler)
    draws = []
    for _ in range(4):  # two startup trials (the random sampler), then TPE's own
        if reseed is not None:
            seed_tpe(sampler, reseed)
        trial = study.ask()
        draws.append(trial.suggest_float("x", 0.0, 1.0))
        study.tell(trial, draws[-1])
    return draws


def test_reseeding_a_tpe_sampler_sets_its_startup_and_its_own_draws() -> None:
    assert _draws(1, reseed=5) == _draws(2, reseed=5)
    assert _draws(1, reseed=None) != _draws(2, reseed=None)


def test_an_enqueued_trial_holds_its_parameters_before_any_is_drawn() -> None:
    study = optuna.create_study()
    study.enqueue_trial({"x": 0.25})
    (waiting,) = study.trials
    assert waiting.params == {} and fixed_params(waiting) == {"x": 0.25}
    assert fixed_params(optuna.trial.create_trial(value=1.0, params={}, distributions={})) == {}
