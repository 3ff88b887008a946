"""The committed meshes are exactly what motor_params.yaml gives, and are sound solids."""

from collections import Counter
import math
from pathlib import Path
import struct

from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_description.meshes import main, mesh_files
import pytest

MESH_DIR = Path(__file__).resolve().parents[1] / 'meshes'
CONFIG = load_robot_config(default_config_path())
REGENERATE = './mecanum run mecanum_description generate_meshes src/mecanum_description/meshes'


def read_stl(data: bytes):
    """Parse binary STL: return (header, [(normal, (v1, v2, v3)), ...])."""
    assert len(data) >= 84, 'shorter than an STL header'
    (count,) = struct.unpack_from('<I', data, 80)
    assert len(data) == 84 + 50 * count, 'size does not match the triangle count'
    triangles = []
    for i in range(count):
        values = struct.unpack_from('<12f', data, 84 + 50 * i)
        triangles.append((values[0:3], (values[3:6], values[6:9], values[9:12])))
    return data[:80], triangles


def signed_volume(triangles) -> float:
    """Volume enclosed (positive when the triangles face outwards)."""
    total = 0.0
    for _, (a, b, c) in triangles:
        total += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                  + a[2] * (b[0] * c[1] - b[1] * c[0]))
    return total / 6.0


def bounding_box(triangles):
    points = [p for _, tri in triangles for p in tri]
    return ([min(p[i] for p in points) for i in range(3)],
            [max(p[i] for p in points) for i in range(3)])


@pytest.mark.parametrize('name', ['chassis.stl', 'wheel.stl'])
def test_committed_meshes_match_the_config(name):
    committed = MESH_DIR / name
    assert committed.is_file(), f'{committed} is missing; run: {REGENERATE}'
    assert committed.read_bytes() == mesh_files(CONFIG)[name], (
        f'{name} is not what motor_params.yaml gives (the config changed?); run: '
        f'{REGENERATE}')


@pytest.mark.parametrize('name', ['chassis.stl', 'wheel.stl'])
def test_meshes_are_small_closed_outward_facing_solids(name):
    data = (MESH_DIR / name).read_bytes()
    assert len(data) < 200_000
    header, triangles = read_stl(data)
    assert not header.startswith(b'solid')   # would be taken for ASCII STL
    # Closed: every edge is used once in each direction by two triangles.
    edges = Counter()
    for _, (a, b, c) in triangles:
        edges.update([(a, b), (b, c), (c, a)])
    assert all(count == 1 and edges[(q, p)] == 1 for (p, q), count in edges.items())
    # Normals are unit length and agree with the winding.
    for normal, (a, b, c) in triangles:
        assert math.dist(normal, (0, 0, 0)) == pytest.approx(1.0, abs=1e-5)
        u = [b[i] - a[i] for i in range(3)]
        v = [c[i] - a[i] for i in range(3)]
        cross = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
        assert sum(n * k for n, k in zip(normal, cross)) > 0


def test_chassis_is_the_configured_box_with_chamfered_edges():
    _, triangles = read_stl((MESH_DIR / 'chassis.stl').read_bytes())
    low, high = bounding_box(triangles)
    half = (CONFIG.chassis_length_m / 2, CONFIG.chassis_width_m / 2,
            CONFIG.chassis_height_m / 2)
    assert low == pytest.approx([-h for h in half], abs=1e-6)
    assert high == pytest.approx(list(half), abs=1e-6)
    box = 8 * half[0] * half[1] * half[2]
    # The chamfers take a little off the box.
    assert 0.9 * box < signed_volume(triangles) < box


def test_wheel_is_the_configured_size_with_roller_bumps():
    _, triangles = read_stl((MESH_DIR / 'wheel.stl').read_bytes())
    r, w = CONFIG.geometry.wheel_radius_m, CONFIG.wheel_width_m
    low, high = bounding_box(triangles)
    # Axis along y; the roller tops reach the wheel radius.
    assert low == pytest.approx([-r, -w / 2, -r], abs=1e-6)
    assert high == pytest.approx([r, w / 2, r], abs=1e-6)
    cylinder = math.pi * r * r * w
    assert 0.8 * cylinder < signed_volume(triangles) < cylinder
    # The rim goes in and out: points on it lie both at the radius and well inside.
    rim = {round(math.hypot(p[0], p[2]), 5) for _, tri in triangles for p in tri
           if math.hypot(p[0], p[2]) > 0.5 * r}
    assert max(rim) == pytest.approx(r, abs=1e-5) and min(rim) < 0.9 * r


def test_generate_meshes_command(tmp_path, capsys):
    assert main([str(tmp_path / 'out')]) == 0
    for name, data in mesh_files(CONFIG).items():
        assert (tmp_path / 'out' / name).read_bytes() == data
    assert 'wrote' in capsys.readouterr().out
    bad = tmp_path / 'bad.yaml'
    bad.write_text('/**:\n  ros__parameters:\n    wheel_radius_m: -1\n')
    assert main([str(tmp_path / 'out2'), '--config', str(bad)]) == 2
    assert 'wheel_radius_m' in capsys.readouterr().err
    assert not (tmp_path / 'out2').exists()
