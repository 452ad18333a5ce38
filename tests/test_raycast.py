"""The ray casting's paths: numpy's (dense, and by arcs) and numba's compiled kernel
(``physics.raycast_kernel``, the optional ``[fast]`` extra), each equal to the others and to
pymunk's one-ray-at-a-time reference, at the edges where rounding decides."""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from test_lidar import random_poses, random_world

from physics import Pose2D, Simulation, WorldSim, load_world, raycast, raycast_kernel

from conftest import compiled_raycast

N_BEAMS = 360
ANGLES = -math.pi + np.arange(N_BEAMS) * (2 * math.pi / N_BEAMS)


def kernel() -> raycast_kernel.Kernel:
    compiled = compiled_raycast()
    if compiled is None:
        pytest.skip("numba is not installed (the optional [fast] extra): nothing compiled")
    return compiled


def cast_with(path: raycast_kernel.Kernel | None, monkeypatch: pytest.MonkeyPatch,
              dense: bool = False) -> Callable[..., np.ndarray]:
    """``raycast.cast`` by ``path`` (None: numpy, every beam on every shape if ``dense``)."""

    def cast(*args: object) -> np.ndarray:
        with monkeypatch.context() as patch:
            patch.setattr(raycast_kernel, "_loaded", [path])
            patch.setattr(raycast, "DENSE_MAX_PAIRS", 10**9 if dense else 0)
            return raycast.cast(*args)  # type: ignore[arg-type]

    return cast


def assert_same(got: np.ndarray, want: np.ndarray, tolerance_m: float) -> None:
    assert got.shape == want.shape
    assert np.array_equal(np.isinf(got), np.isinf(want)), np.argwhere(
        np.isinf(got) != np.isinf(want))[:5]
    finite = np.isfinite(want)
    assert np.max(np.abs(got[finite] - want[finite]), initial=0.0) <= tolerance_m


def scene(seed: int) -> tuple[object, ...]:
    """Lasers among walls and discs at random, with the cases rounding decides: walls of no
    length, walls through a laser, walls seen edge-on, lasers inside discs, each laser's own
    disc left out, ranges that end inside shapes."""
    rng = np.random.default_rng(seed)
    walls, discs, lasers = int(rng.integers(0, 40)), int(rng.integers(0, 50)), 25
    origins = rng.uniform(-4.0, 4.0, size=(lasers, 2))
    a = rng.uniform(-5.0, 5.0, size=(walls, 2))
    b = a + rng.uniform(-3.0, 3.0, size=(walls, 2))
    if walls >= 4:
        b[0] = a[0]  # no length
        a[1], b[1] = origins[0] - (1.0, 0.5), origins[0] + (1.0, 0.5)  # through a laser
        a[2], b[2] = origins[1] + (1.0, 0.0), origins[1] + (2.0, 0.0)  # edge-on to beam 180
    centre = rng.uniform(-4.0, 4.0, size=(discs, 2))
    radius = rng.uniform(0.02, 0.6, size=discs)
    skip = None
    if discs >= 3:
        centre[0] = origins[2] + (0.05, 0.0)  # laser 2 inside disc 0
        skip = rng.integers(-1, discs, size=lasers).astype(np.intp)
        skip[2] = 1  # its own is another: it still reads 0 inside disc 0
    headings = rng.uniform(-4.0, 4.0, size=lasers)
    return (origins, headings, np.cos(ANGLES), np.sin(ANGLES), -math.pi, 2 * math.pi / N_BEAMS,
            float(rng.uniform(0.5, 12.0)), raycast.Walls.of(a, b), centre, radius, skip)


@pytest.mark.parametrize("seed", range(40))
def test_the_compiled_kernel_casts_what_numpy_casts(seed: int,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    args = scene(seed)
    compiled = cast_with(kernel(), monkeypatch)(*args)
    assert_same(compiled, cast_with(None, monkeypatch, dense=True)(*args), 1e-12)
    assert_same(compiled, cast_with(None, monkeypatch)(*args), 1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_the_compiled_kernel_equals_pymunk_in_a_crowd(seed: int,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """80 robots packed in the empty world (``--class 80 --arena``): each laser's kernel
    ranges, other robots included, equal the one-ray-at-a-time reference."""
    monkeypatch.setattr(raycast_kernel, "_loaded", [kernel()])
    world = WorldSim(load_world("empty"), seed=seed)
    rng = np.random.default_rng(seed)
    for index in range(80):
        world.spawn(f"r{index}")
    for name in world.names:
        world.command(name, rng.uniform(-0.3, 0.3), rng.uniform(-2.0, 2.0))
    world.step(4)
    scans = world.cast_scans()
    seen_robots = 0
    for name in world.names:
        reference = world.scan_reference(name)
        raw = Simulation.of(world, name).lidar.raw_ranges_many(
            [Pose2D(*world.ground_truth(name)[:3])], world.footprints(),
            [world.names.index(name)])[0]
        assert_same(raw, reference, 1e-9)
        assert len(scans[name].ranges) == N_BEAMS
        seen_robots += int(np.isfinite(reference).sum() > 0)
    assert seen_robots == 80


@pytest.mark.parametrize("seed", range(2))
def test_a_world_of_many_walls_compiled_equals_the_reference(seed: int,
                                                             monkeypatch: pytest.MonkeyPatch
                                                             ) -> None:
    monkeypatch.setattr(raycast_kernel, "_loaded", [kernel()])
    world = random_world(seed, walls=300, circles=20)
    sim = Simulation(world, seed=0)
    for pose in random_poses(world, 40, seed=seed):
        assert_same(sim.lidar.raw_ranges(pose), sim.lidar.raw_ranges_reference(pose), 1e-9)


def run_python(code: str, raycast_env: str | None,
               data_home: Path) -> subprocess.CompletedProcess[str]:
    env = {key: value for key, value in os.environ.items() if key != raycast_kernel.RAYCAST_ENV}
    env["XDG_DATA_HOME"] = str(data_home)
    if raycast_env is not None:
        env[raycast_kernel.RAYCAST_ENV] = raycast_env
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, timeout=120, check=False)


def test_websim_raycast_chooses_the_path_and_refuses_what_it_does_not_know(
        tmp_path: Path) -> None:
    """numpy unless numba is asked for (it costs a process about 130 MB): installed is not
    asked."""
    which = "from physics import raycast_kernel; print(raycast_kernel.kernel() is not None)"
    assert run_python(which, None, tmp_path).stdout.strip() == "False"
    assert run_python(which, "numpy", tmp_path).stdout.strip() == "False"
    solution = Path(__file__).resolve().parent.parent / "examples/solutions/heading_pid.py"
    for command in (["serve", "--http-port", "1", "--ws-port", "1"],
                    ["grade", "heading_pid", "--out", str(tmp_path / "reports"), "--submission",
                     str(solution.parent), "--", sys.executable, solution.name]):
        bogus = run_python(f"from websim.cli import main; raise SystemExit(main({command!r}))",
                           "fortran", tmp_path)
        assert bogus.returncode == 2, bogus.stderr  # an error, not a submission's 0
        assert "websim: error: WEBSIM_RAYCAST='fortran': expected one of numpy, numba" in \
            bogus.stderr
        assert "Traceback" not in bogus.stderr
    assert not (tmp_path / "reports").exists(), "nothing was graded"
    asked = run_python(which, "NumBa ", tmp_path)
    if compiled_raycast() is None:
        assert asked.returncode != 0 and "numba is not installed" in asked.stderr
    else:
        assert asked.stdout.strip() == "True", asked.stderr


@pytest.mark.skipif(shutil.which("bwrap") is None or os.geteuid() != 0,
                    reason="bubblewrap (bwrap, as root) is not installed: no read-only install")
def test_the_compiled_cast_runs_from_an_install_nobody_may_write(tmp_path: Path) -> None:
    """Every file read-only (a system install, a container's image, numba's cache directory
    unmade): numba keeps no cache, so each process compiles its own, and casts the same."""
    kernel()  # skips without numba
    scan = ("from physics import Simulation, load_world, raycast_kernel;"
            "print(raycast_kernel.kernel() is not None,"
            " *Simulation(load_world('maze'), seed=0).scan().ranges)")
    done = subprocess.run(
        ["bwrap", "--ro-bind", "/", "/", "--dev", "/dev", "--proc", "/proc",
         "--setenv", raycast_kernel.RAYCAST_ENV, "numba",
         "--setenv", "NUMBA_CACHE_DIR", "/nonexistent/numba", "--setenv", "HOME", "/nonexistent",
         sys.executable, "-c", scan],
        capture_output=True, text=True, timeout=300, check=False,
        cwd=Path(__file__).resolve().parent.parent)
    assert done.returncode == 0, done.stderr[-2000:]
    compiled, *ranges = done.stdout.split()
    numpy_path, *numpy_ranges = run_python(scan, "numpy", tmp_path).stdout.split()
    assert (compiled, numpy_path) == ("True", "False")
    assert len(ranges) == 360
    assert np.allclose(np.array(ranges, dtype=float), np.array(numpy_ranges, dtype=float),
                       rtol=0.0, atol=1e-9)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.usefixtures("numpy_raycast")
def test_the_dense_and_the_arc_paths_of_the_batched_cast_agree(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """``physics.raycast``: every beam on every shape, or only the beams of each shape's arc."""
    world = random_world(seed, walls=80, circles=12)
    sim = Simulation(world, seed=0)
    poses = random_poses(world, 30, seed=seed)
    discs = np.array([(pose.x + 0.3, pose.y, 0.11) for pose in poses])  # a robot near each
    own = list(range(len(poses)))
    monkeypatch.setattr(raycast, "DENSE_MAX_PAIRS", 10**9)
    dense = sim.lidar.raw_ranges_many(poses, discs, own)
    monkeypatch.setattr(raycast, "DENSE_MAX_PAIRS", 0)
    arcs = sim.lidar.raw_ranges_many(poses, discs, own)
    assert np.array_equal(np.isinf(dense), np.isinf(arcs))
    finite = np.isfinite(dense)
    assert np.max(np.abs(dense[finite] - arcs[finite])) <= 1e-12
    for pose, row in zip(poses, arcs, strict=True):  # and both equal pymunk's, walls only
        reference = sim.lidar.raw_ranges_reference(pose)
        seen = np.isfinite(reference) & (reference <= row + 1e-9)
        assert np.max(np.abs(row[seen] - reference[seen]), initial=0.0) <= 1e-9
