"""``websim map WORLD --out DIR``: a world as nav2 map_server's ``NAME.yaml`` and ``NAME.pgm``.

The grid is ``/map``'s (``physics.occupancy``), cell for cell: map_server loading the pair
publishes what ``websim serve`` publishes, so AMCL or a planner can run on a websim world on a
real ROS 2 install. NAME is the world file's name (``maze`` for ``worlds/maze.yaml``).

The YAML is map_server's format (mode trinary, negate 0, nav2's default thresholds); the PGM
is 8-bit grey, row 0 the top of the map (the grid's last row: map_server flips it back).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import yaml
from PIL import Image

from physics import ConfigError, load_world
from physics.map_grid import check_resolution
from physics.occupancy import FREE, OCCUPIED, OccupancyGrid, rasterise
from physics.world import resolve_world_path

OCCUPIED_THRESH = 0.65
"""map_server: a pixel darker than this occupancy (``1 - grey / 255``) is occupied (nav2's
default)."""

FREE_THRESH = 0.25
"""map_server: a pixel lighter than this occupancy is free (nav2's default)."""

PIXEL_OCCUPIED = 0
"""Black: occupancy 1.0."""

PIXEL_FREE = 254
"""White (map_saver's 254): occupancy 0.004."""

PIXEL_UNKNOWN = round(255 * (1.0 - (FREE_THRESH + OCCUPIED_THRESH) / 2.0))
"""Grey in the middle of the unknown band (140: occupancy 0.45). Not map_saver's 205: with
free_thresh 0.25, map_server reads 205 (occupancy 0.196) as free (slam_toolbox#587)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``websim map``."""
    parser.add_argument("world", metavar="WORLD",
                        help="world file, or a shipped world's name (empty, maze, corridor)")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR",
                        help="folder for NAME.yaml and NAME.pgm (made if missing)")
    parser.add_argument("--resolution", type=float, default=None, metavar="M",
                        help="cell side in metres (default: the world's map_resolution_m, "
                             "0.05 unless it says)")


def run(args: argparse.Namespace) -> int:
    """Write the pair; print where."""
    world = load_world(args.world)
    resolution = world.map_resolution_m if args.resolution is None \
        else check_resolution("--resolution", args.resolution)
    grid = rasterise(world, resolution, where="--resolution")
    name = resolve_world_path(args.world).stem
    yaml_path, pgm_path = write_map_files(grid, args.out, name,
                                          protect=resolve_world_path(args.world))
    geometry = grid.geometry
    print(f"wrote {yaml_path} and {pgm_path}: {geometry.width} x {geometry.height} cells of "
          f"{geometry.resolution_m:g} m, origin [{geometry.origin_x_m:g}, "
          f"{geometry.origin_y_m:g}]")
    return 0


def map_pixels(grid: OccupancyGrid) -> np.ndarray:
    """The PGM's grey levels, ``uint8`` of shape (height, width), row 0 the map's top."""
    pixels = np.full(grid.cells.shape, PIXEL_UNKNOWN, dtype=np.uint8)
    pixels[grid.cells == FREE] = PIXEL_FREE
    pixels[grid.cells == OCCUPIED] = PIXEL_OCCUPIED
    return np.flipud(pixels)


def map_yaml(grid: OccupancyGrid, image_name: str) -> str:
    """map_server's YAML for ``grid`` whose image is ``image_name`` (beside the YAML)."""
    geometry = grid.geometry
    document = {"image": image_name, "mode": "trinary", "resolution": geometry.resolution_m,
                "origin": [geometry.origin_x_m, geometry.origin_y_m, 0.0], "negate": 0,
                "occupied_thresh": OCCUPIED_THRESH, "free_thresh": FREE_THRESH}
    return yaml.safe_dump(document, sort_keys=False, default_flow_style=None)


def write_map_files(grid: OccupancyGrid, out_dir: Path, name: str,
                    protect: Path | None = None) -> tuple[Path, Path]:
    """Write ``out_dir/name.yaml`` and ``out_dir/name.pgm``.

    Args:
        grid: the map.
        out_dir: the folder (made if missing).
        name: the files' name without extension.
        protect: a file that must not be overwritten (the world file itself, when ``out_dir``
            is the world's folder).

    Raises:
        ConfigError: the folder cannot be made or written, or a file would replace ``protect``.
    """
    yaml_path, pgm_path = out_dir / f"{name}.yaml", out_dir / f"{name}.pgm"
    if protect is not None and yaml_path.resolve() == protect.resolve():
        raise ConfigError(f"--out {out_dir}: {yaml_path} is the world file itself; write the "
                          "map to another folder")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ConfigError(f"--out {out_dir}: cannot make the folder: {error.strerror}") from None
    image = Image.fromarray(map_pixels(grid), mode="L")
    for path, write in ((pgm_path, lambda: image.save(pgm_path, format="PPM")),
                        (yaml_path, lambda: yaml_path.write_text(map_yaml(grid, pgm_path.name),
                                                                 encoding="utf-8"))):
        try:
            write()
        except OSError as error:
            raise ConfigError(f"--out {out_dir}: cannot write {path.name}: "
                              f"{error.strerror}") from None
    return yaml_path, pgm_path
