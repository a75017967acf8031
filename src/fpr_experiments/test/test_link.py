"""The inter-UAV link model (ROS-free, fpr_experiments.link): latency and loss statistics match the configuration
within sampling error, deterministic per seed, independent per directed pair, order preserved per pair; disabled
(ideal) is a pass-through; the outage still drops everything."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fpr_experiments.link import (
    LinkModel,
    LinkOutage,
    LinkRelay,
    PairChannel,
    burst_fraction,
    expected_latency,
    expected_loss,
    lognormal_parameters,
)
from fpr_sim.scenario import LinkConfig, scenario_from_dict

JITTER = LinkConfig(enabled=True, latency_min=0.002, latency_mean=0.004, latency_std=0.006)
BURSTY = LinkConfig(enabled=True, loss=0.02, burst_interval=2.0, burst_duration=0.2, burst_loss=0.9)


def _channel(config: LinkConfig, seed: int = 1) -> PairChannel:
    return LinkModel(config, 3, seed).channel(1, 2)


def test_latency_follows_the_shifted_lognormal():
    channel, n = _channel(JITTER), 20000
    sent = [channel.send(float(k)) for k in range(n)]  # 1 s apart: the FIFO rule never binds
    latency = np.array([s.due - k for k, s in enumerate(sent)])
    assert not any(s.lost for s in sent) and latency.min() >= JITTER.latency_min
    # the mean within 5 standard errors of the configured one
    assert abs(latency.mean() - expected_latency(JITTER)) < 5 * JITTER.latency_std / math.sqrt(n)
    # the empirical CDF at three latencies within 5 binomial standard errors of the lognormal's
    mu, sigma = lognormal_parameters(JITTER.latency_mean, JITTER.latency_std)
    for q in (0.25, 0.5, 0.9):
        value = JITTER.latency_min + math.exp(mu + sigma * math.sqrt(2.0) * _erfinv(2 * q - 1))
        assert abs(np.mean(latency <= value) - q) < 5 * math.sqrt(q * (1 - q) / n)


def _erfinv(y: float) -> float:
    """Inverse error function by bisection (enough for the test)."""
    lo, hi = -6.0, 6.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if math.erf(mid) < y else (lo, mid)
    return 0.5 * (lo + hi)


def test_constant_latency_without_jitter():
    channel = _channel(LinkConfig(enabled=True, latency_min=0.01, latency_mean=0.02))
    assert [channel.send(t).due - t for t in (0.0, 0.5, 1.0)] == pytest.approx([0.03] * 3)


def test_gilbert_elliott_bursts_and_loss_match_the_configuration():
    channel, dt, n = _channel(BURSTY, seed=3), 0.01, 200000
    sent = [channel.send(k * dt) for k in range(n)]
    bad = np.array([s.bad for s in sent])
    lost = np.array([s.lost for s in sent])
    assert bad.mean() == pytest.approx(burst_fraction(BURSTY), rel=0.15)
    starts = np.flatnonzero(np.diff(bad.astype(int)) == 1)
    ends = np.flatnonzero(np.diff(bad.astype(int)) == -1)
    runs = (ends[ends > starts[0]][:len(starts) - 1] - starts[:-1]) * dt if len(starts) > 1 else np.array([])
    assert len(runs) > 500 and runs.mean() == pytest.approx(BURSTY.burst_duration, rel=0.12)
    gaps = np.diff(starts) * dt  # ~900 exponential gaps: standard error ~3.5 %, bursts shorter than dt missed ~2.5 %
    assert gaps.mean() == pytest.approx(BURSTY.burst_interval + BURSTY.burst_duration, rel=0.2)
    assert lost.mean() == pytest.approx(expected_loss(BURSTY), rel=0.1)
    good = ~bad
    assert abs(lost[good].mean() - BURSTY.loss) < 5 * math.sqrt(BURSTY.loss * (1 - BURSTY.loss) / good.sum())
    assert lost[bad].mean() == pytest.approx(BURSTY.burst_loss, abs=0.02)


def test_iid_loss_without_bursts():
    channel, n = _channel(LinkConfig(enabled=True, loss=0.05), seed=4), 40000
    lost = np.array([channel.send(0.02 * k).lost for k in range(n)])
    assert abs(lost.mean() - 0.05) < 5 * math.sqrt(0.05 * 0.95 / n)
    # no memory: a loss does not make the next one likelier
    assert abs(lost[1:][lost[:-1]].mean() - 0.05) < 5 * math.sqrt(0.05 * 0.95 / lost[:-1].sum())


def _fates(model: LinkModel, senders, times, pair):
    out = []
    for sender, t in zip(senders, times, strict=True):
        fates = model.send(sender, t)
        if sender == pair[0]:
            out.append((fates[pair[1]].lost, fates[pair[1]].due))
    return out


def test_deterministic_per_seed():
    config = LinkConfig(enabled=True, latency_min=0.002, latency_mean=0.004, latency_std=0.006, loss=0.05,
                        burst_interval=1.0, burst_duration=0.1)
    times = [0.02 * k for k in range(500)]
    runs = [_fates(LinkModel(config, 3, seed), [1] * 500, times, (1, 2)) for seed in (7, 7, 8)]
    assert runs[0] == runs[1] and runs[0] != runs[2]


def test_pairs_are_independent():
    config = LinkConfig(enabled=True, latency_min=0.002, latency_mean=0.004, latency_std=0.006, loss=0.1,
                        burst_interval=1.0, burst_duration=0.2, burst_loss=0.9)
    times = [0.02 * k for k in range(3000)]
    alone = _fates(LinkModel(config, 3, 5), [1] * 3000, times, (1, 2))
    # other senders' traffic interleaved does not change pair (1, 2)
    mixed_senders = [1 + (k % 3) for k in range(9000)]
    mixed_times = [0.02 * (k // 3) for k in range(9000)]
    assert _fates(LinkModel(config, 3, 5), mixed_senders, mixed_times, (1, 2)) == alone
    # and the two receivers of the same ζ see uncorrelated losses
    model = LinkModel(config, 3, 6)
    both = np.array([[fates[2].lost, fates[3].lost] for fates in (model.send(1, 0.02 * k) for k in range(20000))])
    correlation = np.corrcoef(both.T.astype(float))[0, 1]
    assert abs(correlation) < 0.1  # bursts correlate each pair in time (~20 ζ); the pairs share nothing
    assert both[:, 0].tolist() != both[:, 1].tolist()


def test_order_is_preserved_per_pair():
    channel = _channel(LinkConfig(enabled=True, latency_min=0.001, latency_mean=0.02, latency_std=0.05), seed=2)
    sent = [(t, channel.send(t)) for t in np.arange(0.0, 20.0, 0.001)]
    due = np.array([s.due for _, s in sent])
    assert np.all(np.diff(due) >= 0.0)
    assert all(s.due >= t + s.latency - 1e-12 for t, s in sent)
    assert any(s.due > t + s.latency + 1e-6 for t, s in sent)  # the FIFO rule did hold some back


def test_disabled_or_ideal_is_a_pass_through():
    assert not scenario_from_dict({}).link.enabled  # the ideal profile
    for config in (None, LinkConfig(), LinkConfig(enabled=False, latency_min=1.0, loss=1.0)):
        relay = LinkRelay(3, None, config, seed=1)
        assert relay.model is None
        assert relay.send(2, 5.0, "z") == [(1, "z"), (2, "z"), (3, "z")]
        assert relay.in_flight == 0 and relay.counters.relayed == 3


def test_relay_delivers_when_due_the_own_echo_at_once():
    relay = LinkRelay(3, None, LinkConfig(enabled=True, latency_min=0.05), seed=1)
    assert relay.send(1, 1.0, "a") == [(1, "a")]  # the own echo: local
    assert relay.next_due() == pytest.approx(1.05)
    assert relay.release(1.049) == []
    assert sorted(relay.release(1.05)) == [(2, "a"), (3, "a")]
    zero = LinkRelay(3, None, LinkConfig(enabled=True), seed=1)  # enabled, no latency, no loss: at once
    assert sorted(zero.send(3, 0.0, "b")) == [(1, "b"), (2, "b"), (3, "b")]


def test_relay_applies_the_outage_on_top_of_the_channel():
    relay = LinkRelay(3, LinkOutage(10.0, 13.0), LinkConfig(enabled=True, latency_min=0.05), seed=1)
    assert relay.send(1, 10.0, "x") == [] and relay.send(2, 12.99, "y") == []
    assert relay.release(20.0) == [] and relay.counters.dropped == 2
    assert relay.send(1, 13.0, "z") == [(1, "z")] and sorted(relay.release(13.05)) == [(2, "z"), (3, "z")]
    lossy = LinkRelay(3, None, LinkConfig(enabled=True, loss=1.0), seed=1)
    assert lossy.send(1, 0.0, "w") == [(1, "w")] and lossy.counters.lost == 2


def test_hardware_profile_enables_the_link_and_bad_values_are_refused():
    link = scenario_from_dict({}, realism="hardware").link
    assert link.enabled and 0.001 < expected_latency(link) < 0.05 and 0.001 < expected_loss(link) < 0.1
    for bad, match in [({"loss": 1.5}, "link.loss"), ({"latency_min": -0.1}, "link.latency_min"),
                       ({"latency_std": 0.01}, "latency_mean > 0"), ({"burst_interval": 0.0}, "burst_interval"),
                       ({"burst_interval": 5.0}, "burst_duration")]:
        with pytest.raises(ValueError, match=match):
            scenario_from_dict({"link": {"enabled": True, **bad}})
