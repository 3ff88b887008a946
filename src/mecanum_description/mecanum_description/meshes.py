"""
The robot's meshes, generated from motor_params.yaml (pure, no ROS).

``chassis.stl``: the chassis box (chassis_length_m x chassis_width_m x
chassis_height_m) with every edge chamfered, centred on its origin, x forward,
z up. ``wheel.stl``: a wheel of wheel_radius_m and wheel_width_m, axis along y,
centred on its origin, whose rim is a ring of roller bumps (so its rotation is
visible); the roller tops touch the wheel radius. Binary STL, metres, triangles
wound counter-clockwise seen from outside.

Output is byte-for-byte reproducible: coordinates are rounded to a micrometre
before they are written, so the committed files can be checked against the config.
Regenerate with ``generate_meshes DIRECTORY`` (see :func:`main`).
"""

import argparse
import math
from pathlib import Path
import sys
from typing import List, Optional, Sequence

from mecanum_control.robot_config import (
    default_config_path, load_robot_config, RobotConfig, RobotConfigError)
import numpy as np

#: STL triangle record: normal, three vertices, attribute byte count (50 bytes).
STL_TRIANGLE = np.dtype([('normal', '<f4', (3,)), ('vertices', '<f4', (3, 3)),
                         ('attribute', '<u2')])
ROLLERS = 12
SAMPLES_PER_ROLLER = 8
#: Depth of the valleys between rollers, as a fraction of the wheel radius.
ROLLER_DEPTH = 0.12
#: Chassis edge chamfer, as a fraction of its smallest dimension.
CHAMFER = 0.15


def _rounded(values: np.ndarray) -> np.ndarray:
    """Round to 1e-6 (and turn -0.0 into 0.0) so that output does not depend on libm."""
    return np.round(np.asarray(values, dtype=np.float64), 6) + 0.0


def prism(rings: Sequence[np.ndarray], heights: Sequence[float]) -> np.ndarray:
    """
    Triangles of a closed solid stacked from polygon rings along z.

    Each ring is an (n, 2) array of x, y points, counter-clockwise seen from +z and
    star-shaped around the z axis (the caps are fans from it); heights increase.
    Returns (m, 3, 3) vertices.
    """
    layers = [np.column_stack([ring, np.full(len(ring), z)]) for ring, z in zip(rings, heights)]
    triangles = []
    for lower, upper in zip(layers, layers[1:]):
        for i in range(len(lower)):
            j = (i + 1) % len(lower)
            triangles.append((lower[i], lower[j], upper[j]))
            triangles.append((lower[i], upper[j], upper[i]))
    bottom, top = layers[0], layers[-1]
    bottom_centre = np.array([0.0, 0.0, heights[0]])
    top_centre = np.array([0.0, 0.0, heights[-1]])
    for i in range(len(top)):
        j = (i + 1) % len(top)
        triangles.append((bottom_centre, bottom[j], bottom[i]))
        triangles.append((top_centre, top[i], top[j]))
    return np.array(triangles, dtype=np.float64)


def octagon(half_x: float, half_y: float, corner: float) -> np.ndarray:
    """Rectangle of half extents half_x, half_y with corners cut by corner, CCW."""
    return np.array([(half_x, -half_y + corner), (half_x, half_y - corner),
                     (half_x - corner, half_y), (-half_x + corner, half_y),
                     (-half_x, half_y - corner), (-half_x, -half_y + corner),
                     (-half_x + corner, -half_y), (half_x - corner, -half_y)])


def chassis_triangles(length_m: float, width_m: float, height_m: float) -> np.ndarray:
    """Chamfered box of the given outer size, centred on the origin."""
    chamfer = CHAMFER * min(length_m, width_m, height_m)
    half_x, half_y, half_z = length_m / 2, width_m / 2, height_m / 2
    outer = octagon(half_x, half_y, chamfer)
    inner = octagon(half_x - chamfer, half_y - chamfer, chamfer)
    return prism([inner, outer, outer, inner],
                 [-half_z, -half_z + chamfer, half_z - chamfer, half_z])


def wheel_profile(radius_m: float) -> np.ndarray:
    """Rim outline around the wheel axis: ROLLERS bumps whose tops reach radius_m."""
    count = ROLLERS * SAMPLES_PER_ROLLER
    index = np.arange(count)
    angle = 2.0 * math.pi * index / count
    # Position within a roller: -0.5 .. 0.5, 0 at the roller's top (first sample).
    t = (index % SAMPLES_PER_ROLLER) / SAMPLES_PER_ROLLER
    t = np.where(t >= 0.5, t - 1.0, t)
    depth = ROLLER_DEPTH * radius_m
    rho = radius_m - depth + depth * np.sqrt(1.0 - (2.0 * t) ** 2)
    return np.column_stack([rho * np.cos(angle), rho * np.sin(angle)])


def wheel_triangles(radius_m: float, width_m: float) -> np.ndarray:
    """Wheel of radius_m and width_m, axis along y, centred on the origin."""
    profile = wheel_profile(radius_m)
    along_z = prism([profile, profile], [-width_m / 2, width_m / 2])
    # Rotate -90 deg about x, which takes the z axis to y: (x, y, z) -> (x, z, -y).
    return np.stack([along_z[..., 0], along_z[..., 2], -along_z[..., 1]], axis=-1)


def stl_bytes(triangles: np.ndarray, name: str) -> bytes:
    """Binary STL of (m, 3, 3) triangles (vertices rounded to 1e-6 m)."""
    vertices = _rounded(triangles)
    normals = np.cross(vertices[:, 1] - vertices[:, 0], vertices[:, 2] - vertices[:, 0])
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = _rounded(np.divide(normals, lengths, out=np.zeros_like(normals),
                                 where=lengths > 0))
    records = np.zeros(len(vertices), dtype=STL_TRIANGLE)
    records['normal'] = normals
    records['vertices'] = vertices
    header = f'mecanum_description {name}, metres, generated from motor_params.yaml'
    header = header.encode('ascii')[:80].ljust(80, b' ')
    return header + np.uint32(len(records)).astype('<u4').tobytes() + records.tobytes()


def mesh_files(config: RobotConfig) -> dict:
    """Return the file name -> STL bytes of every mesh, sized from config."""
    return {
        'chassis.stl': stl_bytes(chassis_triangles(
            config.chassis_length_m, config.chassis_width_m, config.chassis_height_m),
            'chassis'),
        'wheel.stl': stl_bytes(wheel_triangles(
            config.geometry.wheel_radius_m, config.wheel_width_m), 'wheel'),
    }


def write_meshes(config: RobotConfig, directory: Path) -> List[Path]:
    """Write every mesh into directory (created if needed); return the paths."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for name, data in mesh_files(config).items():
        path = directory / name
        path.write_bytes(data)
        written.append(path)
    return written


def main(argv: Optional[List[str]] = None) -> int:
    """Command line: generate_meshes DIRECTORY [--config motor_params.yaml]."""
    parser = argparse.ArgumentParser(
        prog='generate_meshes',
        description='Write chassis.stl and wheel.stl, sized from motor_params.yaml.')
    parser.add_argument('directory', type=Path,
                        help='output folder, e.g. src/mecanum_description/meshes')
    parser.add_argument('--config', type=Path, default=None,
                        help='robot config (default: the installed motor_params.yaml)')
    args = parser.parse_args(argv)
    config_path = args.config or default_config_path()
    try:
        config = load_robot_config(config_path)
        paths = write_meshes(config, args.directory)
    except (RobotConfigError, OSError) as error:
        print(f'generate_meshes: {error}', file=sys.stderr)
        return 2
    for path in paths:
        print(f'wrote {path} ({path.stat().st_size} bytes) from {config_path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
