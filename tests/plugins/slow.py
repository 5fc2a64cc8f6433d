"""A method on a machine slower than expected: SysId whose fit takes 1.4 times
its share of the budget. Imported as a plugin by the budget tests
(``--plugin tests/plugins/slow.py``)."""

from __future__ import annotations

import math
import time

from methods import METHODS
from methods.sysid import SysId

#: how much longer than its budget the fit takes
SLOWER = 1.4


@METHODS.add("slow_sysid", "toy")
class SlowSysId(SysId):
    """SysId's fit, then a sleep until 1.4 x the fit's budget has passed (none under a work budget)."""

    def _fit(self, train, experiment, progress):
        budget = progress.remaining()
        super()._fit(train, experiment, progress)
        if math.isfinite(budget):
            time.sleep(max(0.0, SLOWER * budget - progress.elapsed()))
