"""Tests of mecanum_navigation.slam.occupancy_grid_mapping: rays, log-odds, growth, output."""

import math

from mecanum_map_server.map_io import load_map, save_map, world_to_cell
from mecanum_navigation.slam.occupancy_grid_mapping import (
    GridMappingConfig, logit, OccupancyGridMapper, scan_to_rays)
import numpy as np
import pytest

HIT = logit(0.7)
MISS = logit(0.4)


def one_metre_mapper(**overrides):
    """Return a mapper with 1 m cells (easy hand-worked cell indices)."""
    return OccupancyGridMapper(GridMappingConfig(resolution_m=1.0, **overrides))


def log_odds_at(mapper, x, y):
    """Return the log-odds of the cell containing (x, y)."""
    row, col = mapper.cell_of(x, y)
    return float(mapper.log_odds[row, col])


# --- scan_to_rays ---------------------------------------------------------------------

def test_scan_to_rays_sorts_beams_by_hand():
    # Beams every 90 degrees from 0: 0, 90, 180, 270, 360, 450, 540 degrees.
    ranges = [1.0, math.nan, math.inf, 0.05, 5.0, 6.0, 2.0]
    points, is_return = scan_to_rays(ranges, 0.0, math.pi / 2, 0.1, 5.0)
    # NaN, +inf, below range_min (0.05) and above range_max (6.0) are dropped;
    # 5.0 == range_max only clears.
    np.testing.assert_allclose(points, [[1.0, 0.0], [5.0, 0.0], [-2.0, 0.0]], atol=1e-12)
    assert is_return.tolist() == [True, False, True]


def test_scan_to_rays_max_range_m_turns_far_returns_into_clearing():
    points, is_return = scan_to_rays([1.0, 2.0, -math.inf], 0.0, math.pi / 2, 0.1, 5.0,
                                     max_range_m=1.5)
    np.testing.assert_allclose(points, [[1.0, 0.0], [0.0, 1.5]], atol=1e-12)
    assert is_return.tolist() == [True, False]


def test_scan_to_rays_refuses_malformed_scans():
    with pytest.raises(ValueError, match='1-D'):
        scan_to_rays([[1.0, 2.0]], 0.0, 0.1, 0.1, 5.0)
    with pytest.raises(ValueError, match='1-D'):
        scan_to_rays(['a', 'b'], 0.0, 0.1, 0.1, 5.0)
    with pytest.raises(ValueError, match='angle_increment'):
        scan_to_rays([1.0], 0.0, math.nan, 0.1, 5.0)
    with pytest.raises(ValueError, match='range_max'):
        scan_to_rays([1.0], 0.0, 0.1, 0.1, 0.1)
    with pytest.raises(ValueError, match='range_min'):
        scan_to_rays([1.0], 0.0, 0.1, -1.0, 5.0)
    points, is_return = scan_to_rays([], 0.0, 0.1, 0.1, 5.0)
    assert points.shape == (0, 2) and is_return.shape == (0,)


# --- inserting scans ------------------------------------------------------------------

def test_one_beam_frees_the_cells_it_crosses_and_marks_its_end():
    mapper = one_metre_mapper()
    # Laser at (0.5, 0.5) facing +x, a return at 3 m: end point (3.5, 0.5).
    used = mapper.insert_scan((0.5, 0.5, 0.0), [3.0], 0.0, 0.1, 0.1, 10.0)
    assert used == 1
    for x in (0.5, 1.5, 2.5):
        assert log_odds_at(mapper, x, 0.5) == pytest.approx(MISS)
    assert log_odds_at(mapper, 3.5, 0.5) == pytest.approx(HIT)
    assert log_odds_at(mapper, 4.5, 0.5) == 0.0
    assert log_odds_at(mapper, 1.5, 1.5) == 0.0
    grid = mapper.occupancy_grid()
    row, col = mapper.cell_of(3.5, 0.5)
    assert grid[row, col] == 100
    assert grid[row, col - 1] == 0          # p = 0.4 < free_probability 0.5
    assert grid[row + 1, col] == -1         # never observed
    assert np.count_nonzero(grid >= 0) == 4


def test_diagonal_beam_follows_bresenham():
    mapper = one_metre_mapper()
    # From cell (0, 0) to cell (3, 3) at 45 degrees: the diagonal cells only.
    mapper.insert_scan((0.5, 0.5, 0.0), [3.0 * math.sqrt(2.0)], math.pi / 4, 0.1, 0.1, 10.0)
    observed = np.argwhere(mapper.observed)
    cells = {mapper.cell_of(0.5 + k, 0.5 + k) for k in range(4)}
    assert {tuple(c) for c in observed} == cells
    assert log_odds_at(mapper, 3.5, 3.5) == pytest.approx(HIT)
    assert log_odds_at(mapper, 2.5, 2.5) == pytest.approx(MISS)


def test_each_cell_is_updated_once_per_scan_and_a_hit_wins_over_a_miss():
    mapper = one_metre_mapper()
    # Three beams along +x (increment 0): returns at x = 3.5 and 3.7 (both in cell
    # x 3..4) and at 5.5, whose beam also crosses cell x 3..4.
    mapper.insert_scan((0.5, 0.5, 0.0), [3.0, 3.2, 5.0], 0.0, 0.0, 0.1, 10.0)
    assert log_odds_at(mapper, 3.5, 0.5) == pytest.approx(HIT)         # once, not twice
    assert log_odds_at(mapper, 5.5, 0.5) == pytest.approx(HIT)
    assert log_odds_at(mapper, 4.5, 0.5) == pytest.approx(MISS)
    assert log_odds_at(mapper, 1.5, 0.5) == pytest.approx(MISS)        # once per scan
    mapper.insert_scan((0.5, 0.5, 0.0), [3.0], 0.0, 0.0, 0.1, 10.0)
    assert log_odds_at(mapper, 3.5, 0.5) == pytest.approx(2 * HIT)
    assert log_odds_at(mapper, 1.5, 0.5) == pytest.approx(2 * MISS)
    assert mapper.scans_inserted == 2


def test_log_odds_are_clamped():
    mapper = one_metre_mapper()
    for _ in range(30):
        mapper.insert_scan((0.5, 0.5, 0.0), [2.0], 0.0, 0.1, 0.1, 10.0)
    assert log_odds_at(mapper, 2.5, 0.5) == pytest.approx(logit(0.97), rel=1e-6)
    assert log_odds_at(mapper, 0.5, 0.5) == pytest.approx(logit(0.12), rel=1e-6)
    probabilities = mapper.probabilities()
    row, col = mapper.cell_of(2.5, 0.5)
    assert probabilities[row, col] == pytest.approx(0.97, rel=1e-6)


def test_a_max_range_reading_only_clears_up_to_its_end():
    mapper = one_metre_mapper()
    mapper.insert_scan((0.5, 0.5, 0.0), [4.0], 0.0, 0.1, 0.1, 4.0)
    for x in (0.5, 1.5, 2.5, 3.5, 4.5):
        assert log_odds_at(mapper, x, 0.5) == pytest.approx(MISS)
    assert not mapper.occupied_mask().any()


def test_bad_beams_are_ignored_and_a_bad_pose_is_refused():
    mapper = one_metre_mapper()
    used = mapper.insert_scan((0.5, 0.5, 0.0), [math.nan, math.inf, -math.inf, 0.0],
                              0.0, 0.5, 0.1, 10.0)
    assert used == 0
    assert mapper.shape == (0, 0)
    with pytest.raises(ValueError, match='laser_pose'):
        mapper.insert_scan((0.5, math.nan, 0.0), [1.0], 0.0, 0.5, 0.1, 10.0)
    with pytest.raises(ValueError, match='laser_pose'):
        mapper.insert_scan((0.5, 0.5), [1.0], 0.0, 0.5, 0.1, 10.0)
    with pytest.raises(ValueError, match='is_return'):
        mapper.insert_rays((0.0, 0.0), [[1.0, 0.0]], [True, False])


def test_growing_keeps_cells_in_place_and_origin_on_the_grid():
    mapper = OccupancyGridMapper(GridMappingConfig(resolution_m=0.05))
    mapper.insert_scan((0.02, 0.03, 0.0), [1.0], 0.0, 0.1, 0.1, 10.0)
    before = log_odds_at(mapper, 1.02, 0.03)
    assert before == pytest.approx(HIT)
    # Far away in the other direction: the grid grows down and left.
    mapper.insert_scan((-20.0, -15.0, math.pi), [2.0], 0.0, 0.1, 0.1, 10.0)
    assert log_odds_at(mapper, 1.02, 0.03) == before
    assert log_odds_at(mapper, -22.0, -15.0) == pytest.approx(HIT)
    ox, oy = mapper.origin
    assert ox / 0.05 == pytest.approx(round(ox / 0.05), abs=1e-9)
    assert oy / 0.05 == pytest.approx(round(oy / 0.05), abs=1e-9)
    assert ox <= -22.0 and oy <= -15.0


def test_reserve_covers_a_rectangle():
    mapper = one_metre_mapper()
    mapper.reserve(-2.5, 1.0, 3.5, 4.2)
    assert mapper.origin == (-3.0, 1.0)
    assert mapper.shape == (4, 7)
    mapper.reserve(-1.0, 2.0, 1.0, 3.0)     # inside: no change
    assert mapper.shape == (4, 7)
    with pytest.raises(ValueError, match='x_max'):
        mapper.reserve(0.0, 0.0, math.inf, 1.0)


def test_visible_mask_keeps_the_first_wall_a_lidar_sees():
    mapper = one_metre_mapper()
    # Straight rays up and down each column x = 0.5 .. 4.5: rows 3 and 4 seen from
    # below (a 2-cell wall; row 3 twice, as the ray to row 4 crossed it once), row 5
    # from above (a second wall behind the first).
    for x in np.arange(5) + 0.5:
        for y in (4.5, 3.5, 3.5):
            mapper.insert_rays((x, 0.5), [(x, y)], [True])
        mapper.insert_rays((x, 7.5), [(x, 5.5)], [True])
    occupied = mapper.occupied_mask()
    row = {y: mapper.cell_of(2.5, y)[0] for y in (3.5, 4.5, 5.5)}
    assert occupied[row[3.5]].sum() == occupied[row[4.5]].sum() == occupied[row[5.5]].sum() == 5
    # From below: row 3 first, row 4 right behind it (kept), row 5 hidden.
    seen = mapper.visible_mask(2.5, 1.5, 10.0)
    col = mapper.cell_of(2.5, 1.5)[1]
    assert seen[row[3.5], col] and seen[row[4.5], col] and not seen[row[5.5], col]
    # From above: row 5, then row 4 behind it; row 3 hidden.
    seen = mapper.visible_mask(2.5, 6.5, 10.0)
    assert seen[row[5.5], col] and seen[row[4.5], col] and not seen[row[3.5], col]
    assert not (seen & ~occupied).any()
    # Out of reach: row 3 is 1.5 cells away.
    assert not mapper.visible_mask(2.5, 1.5, 1.0).any()
    with pytest.raises(ValueError, match='max_range_m'):
        mapper.visible_mask(2.5, 1.5, math.nan)


# --- output ---------------------------------------------------------------------------

def test_occupancy_map_follows_map_io_conventions_and_saves(tmp_path):
    mapper = OccupancyGridMapper(GridMappingConfig(resolution_m=0.1))
    # Laser at (0.05, 0.05) looking up (+y): a return 1 m above it.
    mapper.insert_scan((0.05, 0.05, math.pi / 2), [1.0], 0.0, 0.1, 0.05, 5.0)
    occupancy = mapper.to_occupancy_map()
    assert occupancy.resolution_m == 0.1
    assert occupancy.origin == (*mapper.origin, 0.0)
    # Row 0 is the bottom: the wall (y = 1.05) is in a higher row than the laser.
    wall = world_to_cell(occupancy, 0.05, 1.05)
    laser = world_to_cell(occupancy, 0.05, 0.05)
    assert wall[0] == laser[0] + 10 and wall[1] == laser[1]
    assert occupancy.data[wall] == 100 and occupancy.data[laser] == 0
    save_map(occupancy, tmp_path / 'slam.yaml')
    loaded = load_map(tmp_path / 'slam.yaml')
    np.testing.assert_array_equal(loaded.data, occupancy.data)
    assert loaded.origin == pytest.approx(occupancy.origin)


def test_percent_output_and_thresholds():
    mapper = one_metre_mapper()
    mapper.insert_scan((0.5, 0.5, 0.0), [2.0], 0.0, 0.1, 0.1, 10.0)
    percent = mapper.occupancy_grid(trinary=False)
    assert percent[mapper.cell_of(2.5, 0.5)] == 70
    assert percent[mapper.cell_of(0.5, 0.5)] == 40
    assert percent[mapper.cell_of(0.5, 1.5)] == -1
    strict = one_metre_mapper(occupied_probability=0.8, free_probability=0.3)
    strict.insert_scan((0.5, 0.5, 0.0), [2.0], 0.0, 0.1, 0.1, 10.0)
    grid = strict.occupancy_grid()
    assert grid[strict.cell_of(2.5, 0.5)] == -1      # 0.7 < 0.8: not yet occupied
    assert grid[strict.cell_of(0.5, 0.5)] == -1      # 0.4 >= 0.3: not yet free


def test_an_empty_mapper_gives_one_unknown_cell():
    occupancy = one_metre_mapper().to_occupancy_map()
    assert occupancy.data.tolist() == [[-1]]
    assert occupancy.origin == (0.0, 0.0, 0.0)


@pytest.mark.parametrize('field, value, message', [
    ('resolution_m', 0.0, 'resolution_m'),
    ('resolution_m', math.nan, 'resolution_m'),
    ('hit_probability', 0.4, 'hit_probability'),
    ('miss_probability', 0.6, 'miss_probability'),
    ('clamp_max_probability', 1.0, 'clamp_max_probability'),
    ('free_probability', 0.9, 'free_probability'),
    ('occupied_probability', True, 'occupied_probability'),
])
def test_config_errors_name_the_field(field, value, message):
    with pytest.raises(ValueError, match=f'GridMappingConfig.{message}'):
        GridMappingConfig(**{field: value})
