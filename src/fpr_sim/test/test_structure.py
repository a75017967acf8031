"""The plant's fast structure dynamics against fpr_model (oracle), and the integrator's energy checks."""

import numpy as np
import pytest
from fpr_model.parameters import default_parameters, parameters_from_dict
from fpr_model.rotations import quat_normalize
from fpr_sim.plant import Plant
from fpr_sim.scenario import scenario_from_dict
from fpr_sim.structure import StructureDynamics, StructureState

from fpr_model import dynamics


def _random_state(rng, n=3, speed=1.0):
    return StructureState(rng.normal(size=3), quat_normalize(rng.normal(size=4)), rng.uniform(0.3, 1.3, n),
                          speed * rng.normal(size=3), speed * rng.normal(size=3), speed * rng.normal(size=n))


@pytest.mark.parametrize("n", [3, 4])
def test_forward_dynamics_matches_fpr_model(n):
    params = parameters_from_dict({"n": n, "platform_mass": 0.3, "joint_offset": 0.0})
    fast = StructureDynamics(params)
    assert fast.fit_residual < 1e-12
    rng = np.random.default_rng(n)
    for _ in range(5):
        state = _random_state(rng, n)
        q, nu = state.configuration(), state.generalized_velocity()
        tau = rng.normal(size=6 + n)
        expected = dynamics.forward_dynamics(params, q, nu, tau)
        assert np.allclose(fast.forward_dynamics(state, tau), expected, atol=1e-10)
        assert np.allclose(fast.mass_matrix(state), dynamics.mass_matrix(params, q), atol=1e-12)
        energy = dynamics.kinetic_energy(params, q, nu) + dynamics.potential_energy(params, q)
        assert fast.energy(state) == pytest.approx(energy, abs=1e-10)


def test_payload_adds_a_point_mass_at_p():
    params = default_parameters()
    fast = StructureDynamics(params, payload_mass=0.3)
    heavy = parameters_from_dict({"platform_mass": params.platform_mass + 0.3, "platform_com": [0.0, 0.0, 0.0],
                                  "platform_inertia": params.platform_inertia.tolist()})
    # a payload at P changes mass and first moment like a heavier platform whose extra mass sits at P
    state = _random_state(np.random.default_rng(0))
    M = fast.body_mass_matrix(state.leg_angles)
    M0 = StructureDynamics(params).body_mass_matrix(state.leg_angles)
    assert np.allclose(M - M0, np.pad(0.3 * np.eye(3), ((0, 6), (0, 6))))
    assert heavy.total_mass == pytest.approx(params.total_mass + 0.3)


def _energy_drift(dt: float, seed: int) -> float:
    scenario = scenario_from_dict({"initial_state": {"mode": "hover"}, "ground": {"enabled": False}})
    plant = Plant(scenario, dt=dt)
    plant.fleet.hover_rotor_state(np.zeros(3))  # no thrust: the free passive structure under gravity
    rng = np.random.default_rng(seed)
    plant.set_state(StructureState(np.zeros(3), np.array([1.0, 0, 0, 0]), rng.uniform(0.6, 1.0, 3),
                                   rng.normal(0, 0.3, 3), rng.normal(0, 0.5, 3), rng.normal(0, 0.5, 3)))
    e0 = plant.structure.energy(plant.state)
    steps = int(round(0.5 / dt))
    for _ in range(steps):
        plant.step()
    return abs(plant.structure.energy(plant.state) - e0)


@pytest.mark.parametrize("seed", [0, 1])
def test_energy_conserved_and_rk4_order(seed):
    coarse = _energy_drift(4e-3, seed)
    fine = _energy_drift(2e-3, seed)
    assert fine < 1e-6  # J, free structure over 0.5 s
    assert coarse / fine > 10.0  # fourth order: ideally 16
