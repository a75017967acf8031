"""A scheduled fault of the inter-UAV link (ROS-free): which information vectors ζ_i get through.

The thesis's emergency case (§4.4.2, l.7128-7132): the UAVs lose their communication and the decentralized
controllers carry on without the others' ζ_j (NC fallback, (4.32)). :class:`LinkOutage` drops every ζ sent during
[``start``, ``end``) [s, simulation time]; the ``info_link`` node applies it between ``/fpr/info`` (where every
controller publishes) and the topic the controllers read (their ``info_input_topic``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class LinkOutage:
    start: float = math.inf  #: [s]
    end: float = math.inf    #: [s]

    def __post_init__(self) -> None:
        if math.isnan(self.start) or math.isnan(self.end) or self.end < self.start:
            raise ValueError(f"link outage needs start <= end, got [{self.start}, {self.end})")

    def passes(self, t: float) -> bool:
        """Does a ζ sent at ``t`` [s] get through?"""
        return not self.start <= t < self.end
