"""Relabel-rate schedules: eps(k), the probability that a sampled transition's goal is replaced by
a hindsight goal during epoch k (1..K), one class per kind, one file each:

- constant.py     eps(k) = eps                                        (HER: 0.8)
- linear.py       eps(k) = 1 - beta1 * (k / K)                        (eq. 9 with beta2 = 0)
- exponential.py  eps(k) = 1 - beta1 * (k / K) ** exp(beta2)          (eq. 9)
- rising.py      eps(k) = 1 - beta1 * ((K + 1 - k) / K) ** exp(beta2)  (eq. 9's rates reversed)
- success.py      eps(k) = clip(1 - beta1 * s(k), eps_min, 1), s(k) the recent train success
- cosine.py       eps(k) = end + (start - end) * (1 + cos(pi k / K)) / 2
- table.py        eps(k) = rates[k - 1], inline, from a file or from another run's log

Each declares its parameters (ranges, docs), rate (checked in [0, 1]), exact mean rate (None when it
adapts), folder tag and label (defaults: its class name and settings) (:class:`Schedule`, base.py); :mod:`registry` maps kind names to classes, including
other packages' (entry point group ``hersd.schedules``) and any class by path (``_target_``).
The paper's equations 9-11 are in equations.py. Imports neither torch nor the config.
"""

from hersd.contract.schedules.base import FLAT_RECORD, Schedule, ScheduleRateError, ScheduleRateRaised, kind_name, param
from hersd.contract.schedules.constant import Constant
from hersd.contract.schedules.cosine import Cosine
from hersd.contract.schedules.equations import (BETA2_LIMIT, MU_EPS_BAND, beta1_for_mean_rate, decay_rate, mean_rate_approx,
                                       mean_rate_exact)
from hersd.contract.schedules.exponential import Exponential
from hersd.contract.schedules.linear import Linear
from hersd.contract.schedules.registry import (DEFAULT, ENTRY_POINT_GROUP, SCHEDULES, TARGET_KEY, known_kinds, registered,
                                      schedule_class, schedule_from_config, schedule_from_record, schedule_rank, settle)
from hersd.contract.schedules.rising import Rising
from hersd.contract.schedules.success import Success
from hersd.contract.schedules.table import Table

__all__ = ["BETA2_LIMIT", "Constant", "Cosine", "DEFAULT", "Exponential", "Linear", "Rising", "Success", "Table", "ENTRY_POINT_GROUP", "FLAT_RECORD", "MU_EPS_BAND", "SCHEDULES", "Schedule",
           "ScheduleRateError", "ScheduleRateRaised", "TARGET_KEY", "beta1_for_mean_rate", "decay_rate", "kind_name", "known_kinds", "mean_rate_approx",
           "mean_rate_exact", "param", "registered", "schedule_class", "schedule_from_config", "schedule_from_record",
           "schedule_rank", "settle"]
