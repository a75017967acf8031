"""The inter-UAV link (ROS-free): which information vectors ζ_i get through to which UAV, and when.

Two effects, applied by the ``info_link`` node between ``/fpr/info`` (where every controller publishes) and one
topic per receiver (each controller's ``info_input_topic``, ``/fpr/uav<j>/info_link``):

- a scheduled fault, :class:`LinkOutage`: every ζ sent during [``start``, ``end``) [s, simulation time] is dropped
  (the thesis's emergency case, §4.4.2, l.7128-7132: the UAVs lose their communication and the decentralized
  controllers carry on without the others' ζ_j, NC fallback (4.32));
- the Wi-Fi channel of the realism profile (``scenario.link``, :class:`fpr_sim.scenario.LinkConfig`), on top:
  :class:`LinkModel`, one :class:`PairChannel` per directed pair (i → j, i ≠ j), each with its own random stream
  from the scenario seed (``SeedSequence([seed, LINK_SEED_STREAM, i, j])``), so the pairs are independent and a
  pair's draws depend only on its own traffic. Per ζ: the Gilbert–Elliott state is advanced to the send time
  (a continuous-time two-state Markov chain: exact transition probabilities over the time since the pair's last
  ζ), the ζ is lost with the state's loss probability, else it is due ``latency_min`` + lognormal jitter later,
  but never before the pair's previous delivery (FIFO: 802.11 delivers a unicast flow in order, a retransmitted
  frame holding back the ones behind it, and a DDS best-effort reader drops a sample older than one it already
  has). The three random draws of a ζ are made whatever their outcome, so the streams stay aligned.

:class:`LinkRelay` is the node's core: the outage, the model and the queue of ζ in flight, released by
:meth:`LinkRelay.release` at (or after) their due time. A UAV's own ζ_i echoed back to it is local (no radio):
delivered at once, only the outage applies (the controllers require their own echo, fpr_control.information).
Disabled (the ``ideal`` profile): every ζ goes to every receiver at once, as the shared DDS topic does.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from fpr_sim.scenario import LinkConfig

#: the link draws from ``SeedSequence([scenario.seed, LINK_SEED_STREAM, sender, receiver])`` (fpr_sim uses 7, 11, 12)
LINK_SEED_STREAM = 50
#: [s] a ζ due within this of the release time is released (float sums of times given in ns)
DUE_TOLERANCE = 1e-9


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


def lognormal_parameters(mean: float, std: float) -> tuple[float, float]:
    """(μ, σ) of the lognormal with this ``mean`` > 0 and ``std`` >= 0 (σ² = ln(1 + std²/mean²))."""
    sigma2 = math.log1p((std / mean) ** 2)
    return math.log(mean) - 0.5 * sigma2, math.sqrt(sigma2)


def burst_fraction(config: LinkConfig) -> float:
    """Stationary probability of the bad (burst) state: T_B / (T_G + T_B)."""
    if not math.isfinite(config.burst_interval):
        return 0.0
    return config.burst_duration / (config.burst_interval + config.burst_duration)


def expected_loss(config: LinkConfig) -> float:
    """Long-run fraction of ζ lost on one pair: π_G · loss + π_B · burst_loss."""
    bad = burst_fraction(config)
    return (1.0 - bad) * config.loss + bad * config.burst_loss


def expected_latency(config: LinkConfig) -> float:
    """Mean latency [s] of a delivered ζ (before the FIFO rule, which only adds to it)."""
    return config.latency_min + config.latency_mean


@dataclass
class Sent:
    """The fate of one ζ on one directed pair."""

    bad: bool               #: the channel was in a burst when it was sent
    lost: bool
    latency: float          #: [s] drawn latency (drawn even when lost)
    due: float | None       #: [s] delivery time (FIFO applied), None when lost


class PairChannel:
    """The channel of one directed pair (see the module doc). Times in seconds of simulation time."""

    def __init__(self, config: LinkConfig, rng: np.random.Generator) -> None:
        self.config = config
        self.rng = rng
        self._bad_fraction = burst_fraction(config)
        bursts = math.isfinite(config.burst_interval)
        #: λ + μ [1/s] of the two-state chain (0: no bursts)
        self._rate = (1.0 / config.burst_interval + 1.0 / config.burst_duration) if bursts else 0.0
        self._jitter = lognormal_parameters(config.latency_mean, config.latency_std) \
            if config.latency_std > 0.0 else None
        self.bad = bool(rng.random() < self._bad_fraction)  # the stationary state at the first ζ
        self._last_time: float | None = None
        self._last_due = -math.inf

    def _advance(self, t: float, u: float) -> None:
        """The chain's state at ``t`` given the state at the last ζ (exact: P(bad at t) = π_B + (1{bad} − π_B)
        e^{−(λ+μ)Δt})."""
        if self._last_time is None or self._rate == 0.0:
            self._last_time = t
            return
        decay = math.exp(-self._rate * max(t - self._last_time, 0.0))
        p_bad = self._bad_fraction + ((1.0 if self.bad else 0.0) - self._bad_fraction) * decay
        self.bad = u < p_bad
        self._last_time = t

    def _latency(self, z: float) -> float:
        config = self.config
        if self._jitter is None:
            return config.latency_min + config.latency_mean
        mu, sigma = self._jitter
        return config.latency_min + math.exp(mu + sigma * z)

    def send(self, t: float) -> Sent:
        """A ζ sent at ``t`` [s]: its state, loss, latency and due time (module doc)."""
        u_state, u_loss = self.rng.random(2)
        z = float(self.rng.standard_normal())
        self._advance(t, float(u_state))
        lost = bool(u_loss < (self.config.burst_loss if self.bad else self.config.loss))
        latency = self._latency(z)
        if lost:
            return Sent(self.bad, True, latency, None)
        due = max(t + latency, self._last_due)
        self._last_due = due
        return Sent(self.bad, False, latency, due)


class LinkModel:
    """One :class:`PairChannel` per directed pair of the n UAVs (ids 1..n), seeded from ``seed``."""

    def __init__(self, config: LinkConfig, n: int, seed: int) -> None:
        self.config, self.n, self.seed = config, n, int(seed)
        self.channels = {(i, j): PairChannel(config, np.random.default_rng(
            np.random.SeedSequence([self.seed, LINK_SEED_STREAM, i, j])))
            for i in range(1, n + 1) for j in range(1, n + 1) if i != j}

    def channel(self, sender: int, receiver: int) -> PairChannel:
        return self.channels[(sender, receiver)]

    def send(self, sender: int, t: float) -> dict[int, Sent]:
        """ζ_sender sent at ``t`` [s]: its fate towards every other UAV."""
        return {j: self.channels[(sender, j)].send(t) for j in range(1, self.n + 1) if j != sender}


@dataclass(order=True)
class _InFlight:
    due: float
    order: int
    receiver: int = field(compare=False)
    payload: Any = field(compare=False)


@dataclass
class LinkCounters:
    relayed: int = 0         #: deliveries made (one per receiver)
    lost: int = 0            #: (ζ, receiver) lost by the channel
    dropped: int = 0         #: ζ dropped by the outage (every receiver)


class LinkRelay:
    """The ``info_link`` node's core (module doc): :meth:`send` when a ζ arrives on ``/fpr/info``,
    :meth:`release` whenever time passes; both return the deliveries to make now, (receiver, payload) pairs."""

    def __init__(self, n: int, outage: LinkOutage | None = None, config: LinkConfig | None = None,
                 seed: int = 0) -> None:
        self.n = n
        self.outage = outage or LinkOutage()
        self.model = LinkModel(config, n, seed) if config is not None and config.enabled else None
        self.counters = LinkCounters()
        self._queue: list[_InFlight] = []
        self._order = 0

    @property
    def in_flight(self) -> int:
        return len(self._queue)

    def next_due(self) -> float:
        """[s] when the next ζ in flight is due (inf: none)."""
        return self._queue[0].due if self._queue else math.inf

    def send(self, sender: int, t: float, payload: Any) -> list[tuple[int, Any]]:
        """ζ of UAV ``sender`` published at ``t`` [s]. A sender outside 1..n is passed to everyone at once (the
        controllers' own guards refuse it and say so)."""
        if not self.outage.passes(t):
            self.counters.dropped += 1
            return []
        receivers = range(1, self.n + 1)
        if self.model is None or not 1 <= sender <= self.n:
            return self._now([(j, payload) for j in receivers])
        now = [(sender, payload)]  # the own echo: local, no radio
        for receiver, sent in self.model.send(sender, t).items():
            if sent.lost:
                self.counters.lost += 1
            else:
                heapq.heappush(self._queue, _InFlight(sent.due, self._order, receiver, payload))
                self._order += 1
        return self._now(now) + self.release(t)

    def release(self, t: float) -> list[tuple[int, Any]]:
        """Every ζ in flight due at or before ``t`` [s], in due order (FIFO per pair, send order on ties)."""
        out = []
        while self._queue and self._queue[0].due <= t + DUE_TOLERANCE:
            item = heapq.heappop(self._queue)
            out.append((item.receiver, item.payload))
        return self._now(out)

    def _now(self, deliveries: Iterable[tuple[int, Any]]) -> list[tuple[int, Any]]:
        deliveries = list(deliveries)
        self.counters.relayed += len(deliveries)
        return deliveries
