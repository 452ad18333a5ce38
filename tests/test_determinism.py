"""Same seed, same run; noise comes only from the simulation's own generator."""

from __future__ import annotations

import numpy as np

from physics import NoiseParams, Simulation, load_world

NOISY = NoiseParams(odom_linear_sigma_mps=0.02, odom_angular_sigma_rps=0.05, scan_sigma_m=0.01)


def rollout(seed: int, mode: str) -> list[tuple]:
    sim = Simulation(load_world("maze"), mode=mode, seed=seed, noise=NOISY)
    rng = np.random.default_rng(99)
    out = []
    for tick in range(150):
        if tick % 10 == 0:
            sim.command(rng.uniform(-0.5, 0.5), rng.uniform(-2.5, 2.5))
        sim.step()
        out.append((tuple(sim.ground_truth()), tuple(sim.odometry()),
                    sim.scan().ranges if tick % 2 else ()))
    return out


def test_same_seed_same_rollout_in_both_modes() -> None:
    for mode in ("kinematic", "dynamic"):
        assert rollout(5, mode) == rollout(5, mode)


def test_different_seed_different_noise() -> None:
    first, second = rollout(5, "kinematic"), rollout(6, "kinematic")
    assert [row[0] for row in first] == [row[0] for row in second], "truth is noiseless"
    assert [row[1] for row in first] != [row[1] for row in second]


def test_odometry_noise_makes_odometry_drift_from_truth() -> None:
    sim = Simulation(load_world("empty"), seed=1, noise=NOISY)
    sim.command(0.3, 0.0)
    sim.step(100)
    truth, odom = sim.ground_truth(), sim.odometry()
    assert (truth.x, truth.y) != (odom.x, odom.y)
    assert abs(odom.x - truth.x) < 0.1


def test_reset_with_seed_replays_the_noise() -> None:
    sim = Simulation(load_world("empty"), seed=1, noise=NOISY)
    sim.command(0.2, 0.4)
    sim.step(30)
    first = (sim.odometry(), sim.scan())
    sim.reset(seed=1)
    sim.command(0.2, 0.4)
    sim.step(30)
    assert (sim.odometry(), sim.scan()) == first


def test_scan_is_the_same_within_a_tick() -> None:
    sim = Simulation(load_world("empty"), seed=1, noise=NOISY)
    assert sim.scan() is sim.scan()


def test_reading_scans_does_not_change_odometry_or_later_scans() -> None:
    def run(read_every: int) -> tuple:
        sim = Simulation(load_world("maze"), seed=3, noise=NOISY)
        sim.command(0.2, 0.3)
        for tick in range(40):
            sim.step()
            if tick % read_every == 0:
                sim.scan()
        return sim.odometry(), sim.scan()

    assert run(1) == run(7) == run(1000)


def test_reset_without_seed_gives_fresh_noise() -> None:
    sim = Simulation(load_world("empty"), seed=1, noise=NOISY)
    first = sim.scan()
    sim.reset()
    assert sim.scan() != first
