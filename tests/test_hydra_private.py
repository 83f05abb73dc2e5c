"""The Hydra internals of sweeps/hydra_private.py still behave as hersd-sweep expects: this
fails when a Hydra release renames or changes them."""

from hydra.core.utils import JobReturn, JobStatus

from sweeps.hydra_private import basic_sweeper_class, grid_overrides, job_error


def test_basic_sweeper_turns_its_params_into_overrides():
    sweeper = basic_sweeper_class()(max_batch_size=None, params={"task": "push", "seed": "range(3)"})
    assert grid_overrides(sweeper) == ["task=push", "seed=range(3)"]
    assert callable(getattr(sweeper, "split_arguments", None)) and callable(getattr(sweeper, "sweep", None))


def test_a_failed_job_return_holds_its_exception():
    error = ValueError("boom")
    result = JobReturn(status=JobStatus.FAILED, _return_value=error)
    assert job_error(result) is error
