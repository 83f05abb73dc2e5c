"""``hersd-search``: an Optuna search of the relabel-rate schedule over the ordinary run store
(docs/SEARCH.md).

Modules, each importing only those before it: ``optuna_private`` (the Optuna internals it relies on),
``storage`` (opening a study storage for writing), ``space`` (what a trial draws: SpaceConfig, the range of each
setting and their checks), ``config`` (the SearchConfig schema and its checks), ``plan`` (what every worker
receives; a trial's run configs), ``study`` (create/load, sampler, pruner, lost trials, enqueued sets, the
trials other workers run), ``objective`` (one trial's runs, reports and pruning), ``workers`` (local processes,
SLURM), ``cli`` (the command). Where a study lives,
what a trial's parameters are and what the study records for the report: :mod:`hersd.contract.study`
(which analysis reads too, opening storages read-only itself).
"""


def main(argv: list[str] | None = None) -> None:
    """``hersd-search`` (:func:`sweeps.search.cli.main`), for scripts installed as ``sweeps.search:main``."""
    from sweeps.search.cli import main as cli_main

    cli_main(argv)
