"""``hydra/sweeper=runstore``: Hydra's basic grid sweeper, aware of hersd's run store.

Hydra only discovers plugins inside the ``hydra_plugins`` package, so this thin module
lives here; the logic it calls is in :mod:`sweeps.plan` (what runs, in which order) and
:mod:`sweeps.launch` (listing, launching, the summary).
"""


import sys
from dataclasses import dataclass, field
from typing import Any, List, Optional

from hydra.core.config_store import ConfigStore

from sweeps.hydra_private import basic_sweeper_class


@dataclass
class RunStoreSweeperConf:
    _target_: str = "hydra_plugins.hersd_sweeper.runstore_sweeper.RunStoreSweeper"
    max_batch_size: Optional[int] = None  # jobs handed to the launcher at once (null: all)
    # the grid: override key -> comma list; or a list of stages, each a grid or a list of grids (sweeps/plan.py)
    params: Any = field(default=None)
    dry_run: bool = False  # list the runs and their state without running them


ConfigStore.instance().store(group="hydra/sweeper", name="runstore", node=RunStoreSweeperConf, provider="hersd")


class RunStoreSweeper(basic_sweeper_class()):
    """Expands the grid (or its stages) seed by seed, then checks, lists or launches the runs
    and ends with a summary (see :func:`sweeps.launch.sweep_runs`)."""

    def __init__(self, max_batch_size: Optional[int], params: Any = None, dry_run: bool = False) -> None:
        super().__init__(max_batch_size=max_batch_size, params=None)
        self.grid = params  # what sweeps.plan.plan_runs expands
        self.dry_run = dry_run

    def sweep(self, arguments: List[str]) -> Any:
        """Run the sweep; a :class:`sweeps.plan.SweepError` ends it with one line on stderr
        (exit 2: bad input, nothing ran; exit 1: some runs failed)."""
        from sweeps.launch import sweep_runs
        from sweeps.plan import SweepError

        try:
            return sweep_runs(self, arguments)
        except SweepError as err:
            print(f"hersd-sweep: error: {err}", file=sys.stderr, flush=True)
            sys.exit(err.exit_code)
