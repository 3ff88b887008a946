"""Tests of the Nav2 map YAML + PGM reader and writer (values worked by hand)."""

import math

from mecanum_map_server.map_io import (
    cell_center, find_map_file, load_map, MapError, OccupancyMap, read_pgm, save_map,
    world_to_cell)
import numpy as np
import pytest
import yaml

YAML_KEYS = {'image': 'm.pgm', 'resolution': 0.05, 'origin': [0.0, 0.0, 0.0], 'negate': 0,
             'occupied_thresh': 0.65, 'free_thresh': 0.25}


def write_map(directory, top_to_bottom_rows, magic='P5', **overrides):
    """
    Write m.pgm (rows given top row first, as in the file) and m.yaml; return the YAML path.

    overrides replace YAML keys; a value of None removes the key.
    """
    rows = [list(row) for row in top_to_bottom_rows]
    height, width = len(rows), len(rows[0])
    if magic == 'P5':
        body = f'P5\n{width} {height}\n255\n'.encode() + bytes(v for row in rows for v in row)
    else:
        lines = [' '.join(str(v) for v in row) for row in rows]
        body = (f'P2\n# hand-made\n{width} {height}\n255\n' + '\n'.join(lines) + '\n').encode()
    (directory / 'm.pgm').write_bytes(body)
    doc = dict(YAML_KEYS)
    for key, value in overrides.items():
        if value is None:
            doc.pop(key, None)
        else:
            doc[key] = value
    path = directory / 'm.yaml'
    path.write_text(yaml.safe_dump(doc))
    return path


def test_round_trip_3x2_and_map_saver_pixels(tmp_path):
    """A 3x2 map survives save + load, and the PGM holds map_saver's 254 / 0 / 205."""
    data = np.array([[0, 100, -1],      # row 0 = bottom row (y lowest)
                     [100, 0, 0]], dtype=np.int8)
    original = OccupancyMap(0.05, (1.5, -2.0, 0.0), data)
    image = save_map(original, tmp_path / 'room.yaml')
    assert image == tmp_path / 'room.pgm'
    # Top image row = the map's top row (row 1): 100 0 0 -> 0 254 254.
    assert image.read_bytes() == b'P5\n3 2\n255\n' + bytes([0, 254, 254, 254, 0, 205])
    doc = yaml.safe_load((tmp_path / 'room.yaml').read_text())
    assert doc == {'image': 'room.pgm', 'mode': 'trinary', 'resolution': 0.05,
                   'origin': [1.5, -2.0, 0.0], 'negate': 0, 'occupied_thresh': 0.65,
                   'free_thresh': 0.196}
    loaded = load_map(tmp_path / 'room.yaml')
    assert loaded.resolution_m == 0.05
    assert loaded.origin == (1.5, -2.0, 0.0)
    assert loaded.data.dtype == np.int8
    np.testing.assert_array_equal(loaded.data, data)


def test_save_with_custom_image_name_and_intermediate_values(tmp_path):
    """Values 1..25 save as free, 65..99 as occupied, 26..64 as unknown (map_saver rules)."""
    data = np.array([[1, 19, 20, 21, 64, 65, 99]], dtype=np.int8)
    save_map(OccupancyMap(0.1, (0.0, 0.0, 0.0), data), tmp_path / 'a.yaml', 'b.pgm',
             free_thresh=0.25)
    # With free_thresh 0.25 map_saver's grey 205 (p = 0.196) would load back as free:
    # unknown is written as the middle of the unknown band, 141 (p = 114/255 = 0.447).
    assert read_pgm(tmp_path / 'b.pgm').tolist() == [[254, 254, 254, 254, 141, 0, 0]]
    save_map(OccupancyMap(0.1, (0.0, 0.0, 0.0), data), tmp_path / 'c.yaml')
    # Default free_thresh 0.196 -> rint(19.6) = 20: 21 is no longer free.
    assert read_pgm(tmp_path / 'c.pgm').tolist() == [[254, 254, 254, 205, 205, 0, 0]]


def test_vertical_flip_top_image_row_is_highest_y(tmp_path):
    """The first image row becomes the last data row, i.e. the cells with the largest y."""
    path = write_map(tmp_path, [[0, 0, 0],           # top: occupied
                                [254, 254, 254]])    # bottom: free
    occupancy = load_map(path)
    assert occupancy.data.tolist() == [[0, 0, 0], [100, 100, 100]]
    # Cell centres: origin 0, 0.05 m cells -> the top row's centre is at y = 0.075.
    assert cell_center(occupancy, 1, 2) == pytest.approx((0.125, 0.075))
    assert world_to_cell(occupancy, 0.125, 0.075) == (1, 2)
    assert occupancy.data[world_to_cell(occupancy, 0.01, 0.09)] == 100


@pytest.mark.parametrize('negate, pixels, expected', [
    # p = (255 - v) / 255: 89 -> 0.651 > 0.65 occupied; 90 -> 0.647 unknown;
    # 191 -> 0.251 unknown; 192 -> 0.247 < 0.25 free; 205 -> 0.196 FREE (Nav2's 0.25 quirk).
    (0, [0, 89, 90, 191, 192, 205, 254, 255], [100, 100, -1, -1, 0, 0, 0, 0]),
    # negate: p = v / 255: 166 -> 0.651 occupied; 165 -> 0.647 unknown; 64 -> 0.251 unknown;
    # 63 -> 0.247 free.
    (1, [255, 166, 165, 64, 63, 0, 128, 205], [100, 100, -1, -1, 0, 0, -1, 100]),
])
def test_trinary_thresholds_and_negate(tmp_path, negate, pixels, expected):
    """Trinary conversion follows map_server exactly, including strict comparisons."""
    occupancy = load_map(write_map(tmp_path, [pixels], negate=negate))
    assert occupancy.data.tolist() == [expected]


def test_unknown_grey_stays_unknown_with_ros1_free_thresh(tmp_path):
    """With free_thresh 0.196 (what save_map writes) grey 205 (p = 0.19608) stays unknown."""
    occupancy = load_map(write_map(tmp_path, [[205, 206]], free_thresh=0.196))
    # 206 -> p = 49/255 = 0.1922 < 0.196: free.
    assert occupancy.data.tolist() == [[-1, 0]]


def test_scale_and_raw_modes(tmp_path):
    """Scale interpolates between the thresholds; raw copies 0..100 and rejects the rest."""
    # 128 -> p = 127/255 = 0.49804; (0.49804 - 0.25) / 0.4 * 100 = 62.01 -> 62.
    # 150 -> p = 0.41176 -> 40.44 -> 40.  0 -> occupied, 255 -> free.
    scale = load_map(write_map(tmp_path, [[128, 150, 0, 255]], mode='scale'))
    assert scale.data.tolist() == [[62, 40, 100, 0]]
    raw = load_map(write_map(tmp_path, [[0, 37, 100, 101, 255]], mode='raw'))
    assert raw.data.tolist() == [[0, 37, 100, -1, -1]]


@pytest.mark.parametrize('mode, values', [
    ('trinary', [-1, 0, 100]),
    ('scale', list(range(101))),
    ('raw', [-1] + list(range(101))),
])
@pytest.mark.parametrize('thresholds', [(0.65, 0.196), (0.65, 0.25), (0.9, 0.1)])
def test_save_then_load_is_lossless_in_every_mode(tmp_path, mode, values, thresholds):
    """Every value a mode can hold comes back the same, with the saved thresholds."""
    rng = np.random.default_rng(7)
    data = rng.choice(values, size=(23, 131)).astype(np.int8)
    data[0, :len(values)] = values  # each value at least once
    original = OccupancyMap(0.05, (-1.25, 2.5, 0.0), data)
    occupied, free = thresholds
    save_map(original, tmp_path / 'm.yaml', mode=mode, occupied_thresh=occupied,
             free_thresh=free)
    assert yaml.safe_load((tmp_path / 'm.yaml').read_text())['mode'] == mode
    loaded = load_map(tmp_path / 'm.yaml')
    assert loaded.data.tolist() == original.data.tolist()
    assert loaded.origin == original.origin and loaded.resolution_m == original.resolution_m
    # Saving what was loaded writes the same image again.
    first = (tmp_path / 'm.pgm').read_bytes()
    save_map(loaded, tmp_path / 'again.yaml', mode=mode, occupied_thresh=occupied,
             free_thresh=free)
    assert (tmp_path / 'again.pgm').read_bytes() == first


def test_scale_pixels_by_hand_and_its_limits(tmp_path):
    """Value 0 and 100 are white and black; unknown cells need consent; tight thresholds fail."""
    data = np.array([[0, 100, 50]], dtype=np.int8)
    save_map(OccupancyMap(0.05, (0.0, 0.0, 0.0), data), tmp_path / 's.yaml', mode='scale',
             occupied_thresh=0.65, free_thresh=0.25)
    pixels = read_pgm(tmp_path / 's.pgm')
    # 50 loads back from p in [0.448, 0.452): greys 255 (1 - p) = 139.7..140.8 -> 140.
    assert pixels[0, 2] == 140
    assert pixels[0, 0] > 255 * (1 - 0.25) and pixels[0, 1] < 255 * (1 - 0.65)
    unknown = OccupancyMap(0.05, (0.0, 0.0, 0.0), np.array([[-1, 0]], dtype=np.int8))
    with pytest.raises(MapError, match='unknown cell'):
        save_map(unknown, tmp_path / 'u.yaml', mode='scale')
    save_map(unknown, tmp_path / 'u.yaml', mode='scale', allow_unknown_loss=True)
    assert read_pgm(tmp_path / 'u.pgm').tolist() == [[205, 254]]
    with pytest.raises(MapError, match='too close'):
        save_map(OccupancyMap(0.05, (0.0, 0.0, 0.0), data), tmp_path / 't.yaml',
                 mode='scale', occupied_thresh=0.5, free_thresh=0.4)
    with pytest.raises(MapError, match='unknown map mode'):
        save_map(OccupancyMap(0.05, (0.0, 0.0, 0.0), data), tmp_path / 't.yaml', mode='gray')


def test_ascii_p2_with_comments_matches_p5(tmp_path):
    """A P2 file with a comment line reads like the equivalent P5 file."""
    rows = [[0, 254, 205], [254, 254, 0]]
    ascii_map = load_map(write_map(tmp_path, rows, magic='P2'))
    binary_map = load_map(write_map(tmp_path, rows, magic='P5'))
    np.testing.assert_array_equal(ascii_map.data, binary_map.data)
    assert ascii_map.data.tolist() == [[0, 0, 100], [100, 0, 0]]


def test_p5_header_comment_and_absolute_image_path(tmp_path):
    """Comments are allowed in the P5 header and an absolute image path is used as is."""
    image = tmp_path / 'elsewhere.pgm'
    image.write_bytes(b'P5 # comment\n# another\n2 1 255\n\x00\xfe')
    path = write_map(tmp_path, [[0]], image=str(image))
    assert load_map(path).data.tolist() == [[100, 0]]


def test_world_to_cell_and_cell_center_with_origin_and_yaw():
    """Cells are found in the grid's own axes, offset and rotated by the origin."""
    occupancy = OccupancyMap(0.5, (1.0, 2.0, 0.0), np.zeros((2, 4), dtype=np.int8))
    assert world_to_cell(occupancy, 1.0, 2.0) == (0, 0)
    assert world_to_cell(occupancy, 2.9, 2.6) == (1, 3)
    assert world_to_cell(occupancy, 3.0, 2.0) is None       # right edge is outside
    assert world_to_cell(occupancy, 0.99, 2.0) is None
    assert cell_center(occupancy, 1, 3) == pytest.approx((2.75, 2.75))
    # Rotated 90 degrees: the grid's x axis points along world +y.
    rotated = OccupancyMap(0.5, (1.0, 2.0, math.pi / 2), np.zeros((2, 4), dtype=np.int8))
    assert cell_center(rotated, 0, 0) == pytest.approx((0.75, 2.25))
    assert cell_center(rotated, 1, 3) == pytest.approx((0.25, 3.75))
    assert world_to_cell(rotated, 0.25, 3.75) == (1, 3)
    assert world_to_cell(rotated, 1.25, 2.25) is None


def test_occupancy_map_rejects_bad_fields():
    """The dataclass itself checks resolution, origin and data shape."""
    with pytest.raises(ValueError, match='resolution'):
        OccupancyMap(0.0, (0.0, 0.0, 0.0), np.zeros((1, 1)))
    with pytest.raises(ValueError, match='origin'):
        OccupancyMap(0.1, (0.0, 0.0), np.zeros((1, 1)))
    with pytest.raises(ValueError, match='2-D'):
        OccupancyMap(0.1, (0.0, 0.0, 0.0), np.zeros(3))


BAD_YAML_CASES = [
    ('missing image', {'image': None}, "missing key 'image'"),
    ('missing resolution', {'resolution': None}, "missing key 'resolution'"),
    ('missing origin', {'origin': None}, "missing key 'origin'"),
    ('missing negate', {'negate': None}, "missing key 'negate'"),
    ('missing occupied_thresh', {'occupied_thresh': None}, "missing key 'occupied_thresh'"),
    ('missing free_thresh', {'free_thresh': None}, "missing key 'free_thresh'"),
    ('zero resolution', {'resolution': 0}, 'bad resolution'),
    ('negative resolution', {'resolution': -0.05}, 'bad resolution'),
    ('text resolution', {'resolution': 'fine'}, 'bad resolution'),
    ('nan resolution', {'resolution': float('nan')}, 'bad resolution'),
    ('origin with 2 numbers', {'origin': [0.0, 0.0]}, "'origin' must be 3 numbers"),
    ('origin with text', {'origin': [0.0, 'a', 0.0]}, "'origin' must be 3 numbers"),
    ('origin scalar', {'origin': 1.0}, "'origin' must be 3 numbers"),
    ('thresholds out of order', {'free_thresh': 0.7}, 'thresholds out of order'),
    ('equal thresholds', {'free_thresh': 0.65}, 'thresholds out of order'),
    ('threshold above 1', {'occupied_thresh': 1.5}, "'occupied_thresh' must be a number"),
    ('negative threshold', {'free_thresh': -0.1}, "'free_thresh' must be a number"),
    ('negate 2', {'negate': 2}, "'negate' must be 0 or 1"),
    ('bad mode', {'mode': 'binary'}, "unknown mode 'binary'"),
    ('empty image name', {'image': ''}, "'image' must be a non-empty file name"),
    ('image missing', {'image': 'nowhere.pgm'}, 'map image not found'),
    ('png by name', {'image': 'map.png'}, 'only PGM'),
]


@pytest.mark.parametrize('overrides, message',
                         [case[1:] for case in BAD_YAML_CASES],
                         ids=[case[0] for case in BAD_YAML_CASES])
def test_bad_yaml_raises_map_error_naming_file(tmp_path, overrides, message):
    """Each malformed map YAML raises MapError naming the YAML file and the problem."""
    path = write_map(tmp_path, [[0, 254]], **overrides)
    with pytest.raises(MapError) as caught:
        load_map(path)
    assert message in str(caught.value)
    assert str(path) in str(caught.value)


BAD_IMAGE_CASES = [
    ('truncated P5', b'P5\n3 2\n255\n\x00\x00\x00\x00', 'truncated PGM: expected 6'),
    ('no pixel data', b'P5\n3 2\n255', 'truncated PGM: no pixel data'),
    ('truncated header', b'P5\n3 2\n', 'truncated PGM header'),
    ('truncated P2', b'P2\n2 2\n255\n0 1 2\n', 'truncated PGM: expected 4'),
    ('P2 value above maxval', b'P2\n2 1\n255\n0 256\n', "bad PGM pixel value '256'"),
    ('wrong magic P6', b'P6\n1 1\n255\n\x00\x00\x00', 'wrong magic'),
    ('wrong magic text', b'hello world', 'wrong magic'),
    ('maxval 65535', b'P5\n1 1\n65535\n\x00\x00', 'maxval is 65535, not 255'),
    ('maxval 15', b'P2\n1 1\n15\n3\n', 'maxval is 15, not 255'),
    ('zero width', b'P5\n0 1\n255\n', 'bad PGM size 0x1'),
    ('non-numeric header', b'P5\nthree 2\n255\n', "bad PGM header value 'three'"),
    ('png magic', b'\x89PNG\r\n\x1a\n\x00\x00', 'PNG'),
]


@pytest.mark.parametrize('content, message', [case[1:] for case in BAD_IMAGE_CASES],
                         ids=[case[0] for case in BAD_IMAGE_CASES])
def test_bad_pgm_raises_map_error_naming_image(tmp_path, content, message):
    """Each malformed image raises MapError naming the image file and the problem."""
    path = write_map(tmp_path, [[0]])
    (tmp_path / 'm.pgm').write_bytes(content)
    with pytest.raises(MapError) as caught:
        load_map(path)
    assert message in str(caught.value)
    assert str(path) in str(caught.value)
    assert str(tmp_path / 'm.pgm') in str(caught.value)


@pytest.mark.parametrize('text, message', [
    ('', 'map YAML is empty'),
    ('image: [unclosed\n', 'YAML syntax error at line 2'),
    ('- just\n- a list\n', 'must be a mapping'),
], ids=['empty', 'syntax error', 'not a mapping'])
def test_bad_yaml_documents(tmp_path, text, message):
    """Empty, unparsable and non-mapping YAML files raise MapError naming the file."""
    path = tmp_path / 'broken.yaml'
    path.write_text(text)
    with pytest.raises(MapError) as caught:
        load_map(path)
    assert message in str(caught.value)
    assert 'broken.yaml' in str(caught.value)


def test_missing_yaml_file(tmp_path):
    """A missing map YAML raises MapError (not OSError) naming it."""
    with pytest.raises(MapError, match='absent.yaml'):
        load_map(tmp_path / 'absent.yaml')


def test_save_refuses_png_and_bad_thresholds(tmp_path):
    """save_map writes PGM only and checks its thresholds."""
    occupancy = OccupancyMap(0.05, (0.0, 0.0, 0.0), np.zeros((1, 1), dtype=np.int8))
    with pytest.raises(MapError, match='only PGM'):
        save_map(occupancy, tmp_path / 'a.yaml', 'a.png')
    with pytest.raises(MapError, match='thresholds out of order'):
        save_map(occupancy, tmp_path / 'a.yaml', free_thresh=0.7)


def test_find_map_file_takes_paths_package_urls_and_names(tmp_path):
    """A path, package://mecanum_map_server/maps/X.yaml and the bare name X agree."""
    by_name = find_map_file('lab_map')
    assert by_name.name == 'lab_map.yaml' and by_name.is_file()
    assert find_map_file('package://mecanum_map_server/maps/lab_map.yaml') == by_name
    assert find_map_file(str(by_name)) == by_name


@pytest.mark.parametrize('text, message', [
    ('moon', 'no map file at .*maps/moon.yaml'),
    ('package://mecanum_navigation', 'expected package://PACKAGE/path'),
    ('package://no_such_package_here/maps/x.yaml', "package 'no_such_package_here' not found"),
    ('/nonexistent/house.yaml', 'no map file at /nonexistent/house.yaml'),
])
def test_find_map_file_names_what_is_missing(text, message):
    """Each unresolvable name gives a MapError saying what was looked for."""
    with pytest.raises(MapError, match=message):
        find_map_file(text)
