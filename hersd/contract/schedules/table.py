"""table: a fixed rate per epoch, eps(k) = rates[k - 1], given inline (``schedule.rates=[...]``), by
a file of rates (``schedule.file=<path>``) or by another run's log (``schedule.from_run=<run dir>``:
the relabel_rate it recorded each epoch). The file and the run are read once, when the config is
made; the run's identity then holds the rates themselves, so a replay is identified by what it computes.
Replaying a success-driven run's realised rates as a plain function of the epoch is
``schedule=table schedule.from_run=<its folder>``."""

from __future__ import annotations

import hashlib
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import List, Optional, Sequence

from hersd.contract.errors import ConfigError
from hersd.contract.schedules.base import Schedule

SOURCES = ("rates", "file", "from_run")


@dataclass
class Table(Schedule):
    kind = "table"
    formula = "eps(k) = rates[k - 1]  (schedule.rates=[...], schedule.file=<path> or schedule.from_run=<run dir>)"
    title = "rate table"
    line = "--"

    rates: Optional[List[float]] = field(default=None, metadata={"doc": "eps(k) for k = 1..K, e.g. [0.9,0.85,0.8]"})
    file: Optional[str] = field(default=None, metadata={"doc": "or a text file of the K rates (whitespace or commas between)"})
    from_run: Optional[str] = field(default=None, metadata={"doc": "or a run's folder: the relabel_rate its log recorded each epoch"})

    def __post_init__(self) -> None:
        given = [name for name in SOURCES if getattr(self, name) is not None]
        if len(given) != 1:
            raise ConfigError(f"schedule=table needs exactly one of schedule.rates, schedule.file, schedule.from_run; "
                              f"got {', '.join(given) or 'none'}")
        if self.rates is not None:
            self.rates = checked_rates(list(self.rates), "schedule.rates")

    def resolve(self, total_epochs: int) -> None:
        if self.file is not None:
            self.rates, self.file = checked_rates(read_rates_file(Path(self.file)), f"schedule.file={self.file}"), None
        elif self.from_run is not None:
            self.rates, self.from_run = checked_rates(read_run_rates(Path(self.from_run)),
                                                      f"schedule.from_run={self.from_run}"), None
        if len(self.rates) != total_epochs:
            raise ConfigError(f"schedule.rates holds {len(self.rates)} rates but epochs={total_epochs}: "
                              "give one rate per epoch")

    def rate(self, k: int, total_epochs: int, train_success: Sequence[float] = ()) -> float:
        return self.rates[k - 1]

    def digest(self) -> str:
        """8 hex digits of the rates: two tables share them only if their rates are the same."""
        return hashlib.sha256(json.dumps(self.rates).encode()).hexdigest()[:8]

    def tag(self) -> str:
        return f"table-{self.digest()}"

    def label(self) -> str:
        return f"table {self.digest()[:4]} μ={sum(self.rates) / len(self.rates):.3g}"


def checked_rates(rates: list, where: str) -> list[float]:
    """``rates`` as floats; ConfigError (one line) unless each is a number in [0, 1] and there is at least one."""
    bad = [rate for rate in rates if isinstance(rate, bool) or not isinstance(rate, (int, float))
           or not math.isfinite(rate) or not 0.0 <= rate <= 1.0]
    if not rates or bad:
        raise ConfigError(f"{where}: rates must be a non-empty list of numbers in [0, 1], got {bad[0] if bad else '[]'}")
    return [float(rate) for rate in rates]


def read_rates_file(path: Path) -> list:
    """The numbers of a text file (whitespace or commas between them)."""
    try:
        words = [word for word in re.split(r"[\s,]+", path.read_text()) if word]
        return [float(word) for word in words]
    except (OSError, ValueError) as err:
        raise ConfigError(f"schedule.file={path}: cannot read its rates ({' '.join(str(err).split())})") from None


def read_run_rates(folder: Path) -> list:
    """The relabel_rate a run's log (``folder``: the run's folder or the log itself) recorded each epoch, shape
    (epochs done,)."""
    from hersd.contract.runlog import RunLogError, read_records

    try:
        return [record["relabel_rate"] for record in read_records(folder).records]
    except (OSError, RunLogError, KeyError) as err:
        raise ConfigError(f"schedule.from_run={folder}: cannot read its rates ({' '.join(str(err).split())})") from None
