"""AMCL end to end on Willow Garage's office floor: scans are ray-cast (nav.raycast) from a true
trajectory, odometry drifts with noise, and the filter must find and keep the true pose."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from bench import amcl as scen
from nav.localization import (
    Amcl,
    AmclConfigError,
    AmclOptions,
    InvalidCovarianceError,
    LocalizationError,
    NoFreeSpaceError,
    NotInitializedError,
)
from nav.types import GridGeometry, OccupancyGrid, Pose2D

if not scen.WILLOW.exists():
    pytest.skip(f"stock map not found at {scen.WILLOW}", allow_module_level=True)

SCAN_HZ = 5.5


@pytest.fixture(scope="module")
def office() -> OccupancyGrid:
    return scen.office_map()


def cluttered(grid: OccupancyGrid, seed: int, boxes: int = 12) -> OccupancyGrid:
    """The same floor with unmapped 0.3 m boxes (people, chairs) for the simulated lidar to see."""
    rng = np.random.default_rng(seed)
    data = grid.data.copy()
    free_r, free_c = np.nonzero(grid.free_mask())
    for i in rng.choice(free_r.size, boxes, replace=False):
        data[free_r[i] : free_r[i] + 3, free_c[i] : free_c[i] + 3] = 100
    return OccupancyGrid(grid.geometry, data)


def run(amcl: Amcl, sc: scen.Scenario, start: int = 0) -> np.ndarray:
    """Feed scans and odometry; (T, 2) translation / heading errors of ``pose_in_map``."""
    errs = []
    for i in range(start, sc.truth.shape[0]):
        odom = Pose2D.from_array(sc.odom[i])
        amcl.update(odom, sc.scans[i], sc.laser_pose)
        errs.append(scen.pose_error(amcl.pose_in_map(odom), sc.truth[i]))
    return np.array(errs)


def test_tracks_drive_from_noisy_initial_pose_with_unmapped_clutter(office: OccupancyGrid) -> None:
    start = Pose2D(12.0, 33.5, 0.0)
    truth = scen.waypoint_trajectory(start, [(20.0, 33.5), (20.0, 30.5), (12.0, 30.5), (12.0, 33.5)])
    rng = np.random.default_rng(11)
    world = cluttered(office, 11)
    sc = scen.Scenario(office, truth, scen.noisy_odometry(truth, rng), scen.synth_scans(world, truth, rng))
    amcl = Amcl(AmclOptions(), office, seed=11)
    guess = Pose2D(12.25, 33.3, 0.1)  # 0.32 m and 5.7 deg off
    amcl.set_initial_pose(guess, np.diag([0.3**2, 0.3**2, 0.15**2]))
    errs = run(amcl, sc)
    settled = errs[30:]  # a few updates (~1.5 m of driving) to converge
    rms = np.sqrt(np.mean(settled**2, axis=0))
    assert rms[0] < 0.06, rms
    assert rms[1] < math.radians(2.0), rms
    assert settled[:, 0].max() < 0.15
    assert amcl.quality > 0.7
    assert amcl.converged


def test_global_localization_while_rotating_in_place(office: OccupancyGrid) -> None:
    opts = AmclOptions()
    starts = [Pose2D(15.95, 33.25, -0.8), Pose2D(10.95, 31.35, 1.9), Pose2D(17.55, 39.05, 3.0)]
    for seed, start in enumerate(starts):
        r, c = office.geometry.world_to_cell(np.array([[start.x, start.y]]))
        assert office.free_mask()[r[0], c[0]]  # the robot stands in mapped free space
        truth = scen.spin_trajectory(start, turns=2.0)
        sc = scen.make_scenario(office, truth, seed)
        amcl = Amcl(opts, office, seed=seed)
        assert amcl.particle_count == opts.global_localization_particles
        errs = run(amcl, sc)
        ok = (errs[:, 0] < 0.2) & (errs[:, 1] < math.radians(5.0))
        # Localized within 20 s of spinning and stays localized to the end.
        first_good = int(np.argmax(ok))
        assert ok[first_good:].all(), (seed, errs[-1])
        assert first_good / SCAN_HZ < 20.0
        assert amcl.particle_count <= opts.max_particles


def test_kld_particle_count_shrinks_as_it_converges(office: OccupancyGrid) -> None:
    """A vague start (1 m, 0.7 rad) and a deliberately weak sensor (10 beams, sigma_hit 0.5 m) so
    that the belief narrows over several updates: the KLD bound follows it down to min_particles."""
    start = Pose2D(15.95, 33.25, 0.5)
    truth = scen.waypoint_trajectory(start, [(18.95, 32.15), (15.95, 33.25)])
    sc = scen.make_scenario(office, truth, 5)
    o = AmclOptions(sigma_hit=0.5, laser_max_beams=10)
    amcl = Amcl(o, office, seed=5)
    amcl.set_initial_pose(start, np.diag([1.0, 1.0, 0.5]))
    spread = amcl.status.bins
    counts = []
    for i in range(truth.shape[0]):
        if amcl.update(Pose2D.from_array(sc.odom[i]), sc.scans[i], sc.laser_pose):
            counts.append(amcl.particle_count)
    assert counts[0] == o.max_particles
    assert any(o.min_particles < c < o.max_particles for c in counts)
    assert all(c == o.min_particles for c in counts[-10:])
    assert amcl.status.bins < spread / 20
    assert scen.pose_error(amcl.pose_in_map(Pose2D.from_array(sc.odom[-1])), truth[-1])[0] < 0.2


def test_kidnapped_robot_recovers_by_random_injection(office: OccupancyGrid) -> None:
    start = Pose2D(12.0, 29.0, 0.0)
    drive = scen.waypoint_trajectory(start, [(16.0, 29.0)])
    spin = scen.spin_trajectory(Pose2D(15.95, 33.25, 1.0), turns=3.0)
    rng = np.random.default_rng(2)
    o1, o2 = scen.noisy_odometry(drive, rng), scen.noisy_odometry(spin, rng)
    last = Pose2D.from_array(o1[-1])
    odom = np.vstack((o1, [last.compose(Pose2D.from_array(p)).as_array() for p in o2]))  # no jump
    truth = np.vstack((drive, spin))
    sc = scen.Scenario(office, truth, odom, scen.synth_scans(office, truth, rng))
    amcl = Amcl(AmclOptions(), office, seed=2)
    amcl.set_initial_pose(start, np.diag([0.05**2, 0.05**2, 0.03**2]))
    before = run(amcl, dataclasses.replace(sc, truth=truth[: len(drive)]))
    assert before[-1, 0] < 0.1 and amcl.quality > 0.8
    injected, qualities, errs = [], [], []
    for i in range(len(drive), len(truth)):
        o = Pose2D.from_array(odom[i])
        if amcl.update(o, sc.scans[i], sc.laser_pose):
            injected.append(amcl.status.injected)
            qualities.append(amcl.quality)
        errs.append(scen.pose_error(amcl.pose_in_map(o), truth[i]))
    e = np.array(errs)
    assert e[0, 0] > 2.0  # the kidnapping was real
    assert min(qualities[:3]) < 0.7  # the scan no longer fits
    assert sum(injected) > 0
    assert e[-20:, 0].max() < 0.15 and e[-20:, 1].max() < math.radians(5.0)
    assert amcl.status.injected == 0  # and injection stops once localized


def test_beam_model_tracks(office: OccupancyGrid) -> None:
    start = Pose2D(12.0, 30.5, 0.0)
    truth = scen.waypoint_trajectory(start, [(15.0, 30.5)])
    sc = scen.make_scenario(office, truth, 4)
    o = AmclOptions(laser_model_type="beam", min_particles=100, max_particles=300)
    amcl = Amcl(o, office, seed=4)
    amcl.set_initial_pose(Pose2D(12.1, 30.4, 0.05), np.diag([0.15**2, 0.15**2, 0.1**2]))
    errs = run(amcl, sc)
    assert errs[-10:, 0].max() < 0.1
    assert errs[-10:, 1].max() < math.radians(3.0)


def test_omnidirectional_model_tracks_strafing(office: OccupancyGrid) -> None:
    """The omni base strafes sideways (heading fixed) then drives diagonally."""
    y = np.arange(0.0, 3.0, 0.05)
    leg1 = np.column_stack((np.full_like(y, 14.0), 29.5 + y, np.full_like(y, 0.3)))
    d = np.arange(0.05, 2.0, 0.05)
    leg2 = np.column_stack((14.0 + d * 0.8, leg1[-1, 1] - d * 0.6, np.full_like(d, 0.3)))
    truth = np.vstack((leg1, leg2))
    sc = scen.make_scenario(office, truth, 9)
    amcl = Amcl(AmclOptions(robot_model_type="omnidirectional"), office, seed=9)
    amcl.set_initial_pose(Pose2D.from_array(truth[0]), np.diag([0.1**2, 0.1**2, 0.05**2]))
    errs = run(amcl, sc)
    assert np.sqrt(np.mean(errs[10:] ** 2, axis=0))[0] < 0.06
    assert errs[10:, 1].max() < math.radians(3.0)


def test_update_gating_and_transforms(office: OccupancyGrid) -> None:
    start = Pose2D(12.0, 33.5, 0.2)
    sc = scen.make_scenario(office, np.array([start.as_array()] * 2), 1)
    amcl = Amcl(AmclOptions(), office, seed=1)
    amcl.set_initial_pose(start, np.diag([0.02, 0.02, 0.01]))
    with pytest.raises(NotInitializedError):
        amcl.map_to_odom()
    odom0 = Pose2D(1.0, -2.0, 0.5)
    # Right after set_initial_pose the estimate refers to the current odometry pose.
    est, _ = amcl.estimate()
    assert amcl.map_to_odom(odom0).compose(odom0).distance_to(est) < 1e-9
    assert amcl.update(odom0, sc.scans[0], sc.laser_pose)  # first scan always updates
    assert not amcl.update(Pose2D(1.1, -2.0, 0.6), sc.scans[1], sc.laser_pose)  # 0.1 m, 0.1 rad
    assert amcl.update(Pose2D(1.0, -2.0, 0.75), sc.scans[1], sc.laser_pose)  # 0.25 rad
    assert amcl.update(Pose2D(1.26, -2.0, 0.75), sc.scans[1], sc.laser_pose)  # 0.26 m
    est, cov = amcl.estimate()
    assert cov.shape == (3, 3) and np.all(np.linalg.eigvalsh(cov) >= -1e-12)
    odom_now = Pose2D(1.5, -1.0, 1.0)
    moved = amcl.pose_in_map(odom_now)
    assert amcl.map_to_odom().compose(odom_now).distance_to(moved) < 1e-9
    assert amcl.particles.shape == (amcl.particle_count, 3)
    assert amcl.weights.sum() == pytest.approx(1.0)
    with pytest.raises(ValueError):
        amcl.particles[0, 0] = 1.0  # read-only view
    all_mean, _ = amcl.estimate_all()
    assert all_mean.distance_to(est) < 0.3


def test_errors(office: OccupancyGrid) -> None:
    amcl = Amcl(AmclOptions(), office, seed=0)
    with pytest.raises(InvalidCovarianceError):
        amcl.set_initial_pose(Pose2D(), np.diag([1.0, -1.0, 1.0]))
    with pytest.raises(InvalidCovarianceError):
        amcl.set_initial_pose(Pose2D(), np.eye(2))
    with pytest.raises(AmclConfigError):
        AmclOptions(min_particles=3000)
    with pytest.raises(AmclConfigError):
        AmclOptions(laser_model_type="sonar")
    with pytest.raises(AmclConfigError):
        AmclOptions.from_mapping({"max_particle": 10})
    o = AmclOptions.from_mapping({"robot_model_type": "nav2_amcl::OmniMotionModel", "alpha5": 0.1})
    assert o.robot_model_type == "omnidirectional" and o.alpha5 == 0.1
    with pytest.raises(LocalizationError):
        amcl.update(
            Pose2D(math.nan, 0.0, 0.0), scen.make_scenario(office, np.zeros((1, 3)), 0).scans[0], Pose2D()
        )
    # A scan with no returns updates nothing but the motion, and breaks nothing.
    amcl.set_initial_pose(Pose2D(12.0, 33.5, 0.0), np.diag([0.01, 0.01, 0.01]))
    blind = scen.make_scenario(office, np.zeros((1, 3)), 0).scans[0]
    blind = dataclasses.replace(blind, ranges=np.full_like(blind.ranges, np.inf))
    assert amcl.update(Pose2D(), blind, Pose2D())
    assert np.all(np.isfinite(amcl.weights)) and amcl.quality == 0.0
    walls = OccupancyGrid(GridGeometry(0.1, 5, 5), np.full((5, 5), 100, dtype=np.int8))
    with pytest.raises(NoFreeSpaceError):
        Amcl(AmclOptions(), walls)


def test_initial_pose_from_options_and_determinism(office: OccupancyGrid) -> None:
    o = AmclOptions(set_initial_pose=True, initial_pose_x=12.0, initial_pose_y=33.5, initial_pose_yaw=0.4)
    a, b = Amcl(o, office, seed=3), Amcl(o, office, seed=3)
    assert a.particle_count == o.max_particles
    np.testing.assert_allclose(a.particles.mean(axis=0), [12.0, 33.5, 0.4], atol=0.05)
    np.testing.assert_allclose(np.cov(a.particles.T), np.diag([0.25, 0.25, (math.pi / 12) ** 2]), atol=0.03)
    sc = scen.make_scenario(office, np.array([[12.0, 33.5, 0.4]]), 0)
    a.update(Pose2D(), sc.scans[0], sc.laser_pose)
    b.update(Pose2D(), sc.scans[0], sc.laser_pose)
    np.testing.assert_array_equal(a.particles, b.particles)
