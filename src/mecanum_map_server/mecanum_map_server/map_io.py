"""
Nav2 map_server map files: the map YAML and its 8-bit PGM image (pure, no ROS).

A map is a pair of files, exactly as nav2_map_server's map_server and map_saver use them::

    image: lab_map.pgm          # relative to the YAML's directory (or absolute)
    mode: trinary               # optional: trinary (default) | scale | raw
    resolution: 0.05            # metres per cell
    origin: [-0.5, -0.5, 0.0]   # x_m, y_m, yaw_rad of the image's lower-left pixel
    negate: 0                   # 1: white is occupied, black is free
    occupied_thresh: 0.65
    free_thresh: 0.196

Loading follows map_server's conversion: with ``shade = value / 255`` and
``p = 1 - shade`` (``p = shade`` when negate), trinary mode gives 100 when
``p > occupied_thresh``, 0 when ``p < free_thresh`` and -1 (unknown) otherwise; scale
mode gives ``rint((p - free_thresh) / (occupied_thresh - free_thresh) * 100)`` between the
thresholds; raw mode takes the pixel value itself when it is 0..100, else -1. The image's
top row is the map's highest y: the rows are flipped when loading, so ``data[0]`` is the
BOTTOM row (ROS OccupancyGrid order). Only PGM images (P5 binary and P2 ASCII, maxval
255) are read here; PNG and other formats raise MapError.

Saving writes a P5 PGM and a YAML with negate 0, as map_saver does, in one of the modes:

- trinary (the default, map_saver's): 254 for free (0..rint(100 free_thresh)), 0 for
  occupied (rint(100 occupied_thresh)..100) and 205 for everything else. free_thresh
  defaults to 0.196 (ROS 1 map_saver's value) rather than Nav2's 0.25, because with 0.25
  the unknown grey 205 (p = 50/255 = 0.196) loads back as FREE, in this module and in
  Nav2 alike; when the given thresholds make a grey load as something else, the middle
  grey of the right band is written instead (cells_to_pixels).
- scale: for each value 0..100 the grey that loads back as that value with the written
  thresholds (the thresholds are at least 0.0045 per value apart, so such a grey always
  exists, see scale_pixel_table). A PGM has no alpha channel, which is how Nav2 marks
  unknown cells in scale mode, so unknown cells are written 205 and come back as a value:
  save_map refuses them unless allow_unknown_loss.
- raw: the value itself as the grey (0..100), 255 for unknown.

Round trips are lossless: loading what save_map wrote gives back the same cells in every
mode, for all values the mode can hold (trinary: -1, 0 and 100; scale: 0..100; raw:
-1..100); test_map_io checks each.

Frames follow REP-103: x forward/east, y left/north, yaw counter-clockwise, metres and
radians throughout.
"""

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Optional, Tuple, Union

import numpy as np
import yaml

PathLike = Union[str, Path]

#: OccupancyGrid cell values.
FREE = 0
OCCUPIED = 100
UNKNOWN = -1

#: Trinary PGM pixel values written by map_saver.
PIXEL_FREE = 254
PIXEL_OCCUPIED = 0
PIXEL_UNKNOWN = 205

#: Thresholds written by save_map (see the module docstring for free_thresh).
SAVE_OCCUPIED_THRESH = 0.65
SAVE_FREE_THRESH = 0.196

MODES = ('trinary', 'scale', 'raw')
_REQUIRED_KEYS = ('image', 'resolution', 'origin', 'negate', 'occupied_thresh', 'free_thresh')
_PNG_MAGIC = b'\x89PNG\r\n\x1a\n'
_WHITESPACE = b' \t\r\n\v\f'


class MapError(ValueError):
    """A malformed map YAML or image; the message names the file and the problem."""


class MapImageError(MapError):
    """A map's image is missing, unreadable or not a PGM (its YAML was fine)."""


@dataclass(eq=False)
class OccupancyMap:
    """
    A 2-D occupancy grid in ROS OccupancyGrid conventions.

    resolution_m is the cell size in metres; origin is (x_m, y_m, yaw_rad) of the
    lower-left corner of cell (row 0, col 0) in the map frame; data is an int8 array of
    shape (height, width) holding -1 (unknown) or 0..100 (occupancy percent), where row 0
    is the BOTTOM row (lowest y) and column 0 the lowest x of the map.
    """

    resolution_m: float
    origin: Tuple[float, float, float]
    data: np.ndarray

    def __post_init__(self) -> None:
        """Check the fields and store data as a C-contiguous int8 array."""
        if not _is_number(self.resolution_m) or not (
                math.isfinite(self.resolution_m) and self.resolution_m > 0.0):
            raise ValueError(f'resolution_m must be a positive number, not {self.resolution_m!r}')
        origin = tuple(self.origin)
        if len(origin) != 3 or not all(_is_number(v) and math.isfinite(v) for v in origin):
            raise ValueError(f'origin must be 3 finite numbers, not {self.origin!r}')
        self.resolution_m = float(self.resolution_m)
        self.origin = tuple(float(v) for v in origin)
        data = np.asarray(self.data)
        if data.ndim != 2 or data.shape[0] < 1 or data.shape[1] < 1:
            raise ValueError(f'data must be a non-empty 2-D array, not shape {data.shape}')
        self.data = np.ascontiguousarray(data, dtype=np.int8)

    @property
    def width(self) -> int:
        """Return the number of columns (cells along the map's x axis)."""
        return int(self.data.shape[1])

    @property
    def height(self) -> int:
        """Return the number of rows (cells along the map's y axis)."""
        return int(self.data.shape[0])


def world_to_cell(occupancy_map: OccupancyMap, x: float,
                  y: float) -> Optional[Tuple[int, int]]:
    """
    Return the (row, col) of the cell containing map-frame point (x, y) in metres.

    Row 0 is the bottom row. Returns None when the point is outside the grid. A point on
    a boundary between cells belongs to the cell above / to the right of it.
    """
    local_x, local_y = _to_grid_frame(occupancy_map, x, y)
    col = math.floor(local_x / occupancy_map.resolution_m)
    row = math.floor(local_y / occupancy_map.resolution_m)
    if 0 <= row < occupancy_map.height and 0 <= col < occupancy_map.width:
        return row, col
    return None


def cell_center(occupancy_map: OccupancyMap, row: int, col: int) -> Tuple[float, float]:
    """Return the map-frame (x, y) in metres of the centre of cell (row, col); row 0 = bottom."""
    local_x = (col + 0.5) * occupancy_map.resolution_m
    local_y = (row + 0.5) * occupancy_map.resolution_m
    origin_x, origin_y, yaw = occupancy_map.origin
    cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
    return (origin_x + cos_yaw * local_x - sin_yaw * local_y,
            origin_y + sin_yaw * local_x + cos_yaw * local_y)


def load_map(yaml_path: PathLike) -> OccupancyMap:
    """
    Read a Nav2 map YAML and its PGM image into an OccupancyMap.

    Raises MapError, naming the file, for any malformed YAML, missing key, bad value,
    missing or unreadable image, non-PGM image, or malformed PGM.
    """
    yaml_path = Path(yaml_path)
    try:
        text = yaml_path.read_text(encoding='utf-8')
    except OSError as error:
        raise MapError(f'{yaml_path}: cannot read map YAML: {error.strerror or error}') from None
    except UnicodeDecodeError:
        raise MapError(f'{yaml_path}: map YAML is not UTF-8 text') from None
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise MapError(f'{yaml_path}: YAML syntax error{_yaml_position(error)}') from None
    if doc is None:
        raise MapError(f'{yaml_path}: map YAML is empty')
    if not isinstance(doc, dict):
        raise MapError(f'{yaml_path}: map YAML must be a mapping of keys '
                       f'({", ".join(_REQUIRED_KEYS)}), not {type(doc).__name__}')
    for key in _REQUIRED_KEYS:
        if key not in doc:
            raise MapError(f"{yaml_path}: missing key '{key}' "
                           f'(required: {", ".join(_REQUIRED_KEYS)}; optional: mode)')

    image = doc['image']
    if not isinstance(image, str) or not image.strip():
        raise MapError(f"{yaml_path}: 'image' must be a non-empty file name, not {image!r}")
    resolution = doc['resolution']
    if not _is_number(resolution) or not (math.isfinite(resolution) and resolution > 0.0):
        raise MapError(f'{yaml_path}: bad resolution {resolution!r}: '
                       'must be a positive number of metres per cell')
    origin = doc['origin']
    if (not isinstance(origin, (list, tuple)) or len(origin) != 3
            or not all(_is_number(v) and math.isfinite(v) for v in origin)):
        raise MapError(f"{yaml_path}: 'origin' must be 3 numbers [x_m, y_m, yaw_rad], "
                       f'not {origin!r}')
    negate = doc['negate']
    if isinstance(negate, bool):
        negate = int(negate)
    if not isinstance(negate, int) or negate not in (0, 1):
        raise MapError(f"{yaml_path}: 'negate' must be 0 or 1, not {doc['negate']!r}")
    thresholds = {}
    for key in ('occupied_thresh', 'free_thresh'):
        value = doc[key]
        if not _is_number(value) or not 0.0 <= value <= 1.0:
            raise MapError(f"{yaml_path}: '{key}' must be a number in [0, 1], not {value!r}")
        thresholds[key] = float(value)
    occupied_thresh, free_thresh = thresholds['occupied_thresh'], thresholds['free_thresh']
    if not free_thresh < occupied_thresh:
        raise MapError(f'{yaml_path}: thresholds out of order: free_thresh {free_thresh} '
                       f'must be below occupied_thresh {occupied_thresh}')
    mode = doc.get('mode', 'trinary')
    if mode not in MODES:
        raise MapError(f"{yaml_path}: unknown mode {mode!r} (expected one of {', '.join(MODES)})")

    image_path = Path(image).expanduser()
    if not image_path.is_absolute():
        image_path = yaml_path.parent / image_path
    try:
        pixels = read_pgm(image_path)
    except MapError as error:
        raise MapImageError(f'{yaml_path}: {error}') from None
    cells = pixels_to_cells(pixels, mode, bool(negate), occupied_thresh, free_thresh)
    return OccupancyMap(float(resolution), tuple(float(v) for v in origin), np.flipud(cells))


def save_map(occupancy_map: OccupancyMap, yaml_path: PathLike, image_name: Optional[str] = None,
             occupied_thresh: float = SAVE_OCCUPIED_THRESH,
             free_thresh: float = SAVE_FREE_THRESH, mode: str = 'trinary',
             allow_unknown_loss: bool = False) -> Path:
    """
    Write occupancy_map as map_saver does: a YAML and a P5 PGM beside it.

    image_name is the PGM's file name, written in the YAML's directory (default: the
    YAML's stem + '.pgm'). mode is 'trinary', 'scale' or 'raw' (module docstring).
    Returns the image path.
    """
    yaml_path = Path(yaml_path)
    if image_name is None:
        image_name = yaml_path.stem + '.pgm'
    if Path(image_name).suffix.lower() != '.pgm':
        raise MapError(f'{yaml_path}: image {image_name!r}: only PGM images are written here')
    if not 0.0 <= free_thresh < occupied_thresh <= 1.0:
        raise MapError(f'{yaml_path}: thresholds out of order: need 0 <= free_thresh '
                       f'{free_thresh} < occupied_thresh {occupied_thresh} <= 1')
    if mode not in MODES:
        raise MapError(f'{yaml_path}: unknown map mode {mode!r} (expected one of '
                       f'{", ".join(MODES)})')
    if mode == 'trinary':
        try:
            pixels = cells_to_pixels(occupancy_map.data, occupied_thresh, free_thresh)
        except ValueError as error:
            raise MapError(f'{yaml_path}: {error}') from None
    elif mode == 'raw':
        values = np.asarray(occupancy_map.data).astype(np.int16)
        pixels = np.where((values >= 0) & (values <= 100), values, 255).astype(np.uint8)
    else:
        values = np.asarray(occupancy_map.data).astype(np.int16)
        unknown = (values < 0) | (values > 100)
        if unknown.any() and not allow_unknown_loss:
            raise MapError(f'{yaml_path}: {int(unknown.sum())} unknown cell(s) cannot be '
                           'stored in a scale-mode PGM (it has no alpha channel); save in '
                           'trinary or raw mode, or allow the loss')
        try:
            table = scale_pixel_table(occupied_thresh, free_thresh)
        except ValueError as error:
            raise MapError(f'{yaml_path}: {error}') from None
        pixels = np.where(unknown, PIXEL_UNKNOWN, table[np.clip(values, 0, 100)])
        pixels = pixels.astype(np.uint8)
    image_path = yaml_path.parent / image_name
    write_pgm(image_path, np.flipud(pixels))
    doc = {
        'image': image_name,
        'mode': mode,
        'resolution': occupancy_map.resolution_m,
        'origin': [float(v) for v in occupancy_map.origin],
        'negate': 0,
        'occupied_thresh': float(occupied_thresh),
        'free_thresh': float(free_thresh),
    }
    yaml_path.write_text(yaml.safe_dump(doc, sort_keys=False, default_flow_style=None),
                         encoding='utf-8')
    return image_path


def pixels_to_cells(pixels: np.ndarray, mode: str = 'trinary', negate: bool = False,
                    occupied_thresh: float = 0.65, free_thresh: float = 0.25) -> np.ndarray:
    """
    Convert 8-bit grey pixel values to OccupancyGrid values as map_server does.

    The array keeps its row order (no flip). mode is 'trinary', 'scale' or 'raw'.
    """
    values = np.asarray(pixels, dtype=np.float64)
    shade = values / 255.0
    occ = shade if negate else 1.0 - shade
    if mode == 'raw':
        raw = np.round(shade * 255.0)
        return np.where((raw >= 0) & (raw <= 100), raw, UNKNOWN).astype(np.int8)
    if mode == 'trinary':
        middle = np.full(values.shape, UNKNOWN, dtype=np.float64)
    elif mode == 'scale':
        middle = np.rint((occ - free_thresh) / (occupied_thresh - free_thresh) * 100.0)
    else:
        raise ValueError(f'unknown map mode {mode!r} (expected one of {", ".join(MODES)})')
    cells = np.where(occ > occupied_thresh, OCCUPIED, np.where(occ < free_thresh, FREE, middle))
    return cells.astype(np.int8)


def cells_to_pixels(cells: np.ndarray, occupied_thresh: float = SAVE_OCCUPIED_THRESH,
                    free_thresh: float = SAVE_FREE_THRESH) -> np.ndarray:
    """
    Convert OccupancyGrid values to trinary pixels; no flip.

    map_saver's greys (254 free, 0 occupied, 205 unknown) where they load back as such
    with these thresholds; otherwise the middle grey of the band that does (e.g. 205 is
    free with free_thresh 0.25, so unknown is written as the grey of p = 0.45 then).
    """
    values = np.asarray(cells).astype(np.int16)
    free_int = int(np.rint(free_thresh * 100.0))
    occupied_int = int(np.rint(occupied_thresh * 100.0))
    loaded = pixels_to_cells(np.arange(256), 'trinary', False, occupied_thresh, free_thresh)
    greys = {}
    for value, usual in ((FREE, PIXEL_FREE), (OCCUPIED, PIXEL_OCCUPIED),
                         (UNKNOWN, PIXEL_UNKNOWN)):
        band = matches_of(loaded, value)
        if band.size == 0:
            raise ValueError(f'trinary mode cannot store {value} with thresholds free '
                             f'{free_thresh}, occupied {occupied_thresh}')
        greys[value] = usual if usual in band else band[band.size // 2]
    pixels = np.full(values.shape, greys[UNKNOWN], dtype=np.uint8)
    pixels[(values >= 0) & (values <= free_int)] = greys[FREE]
    pixels[(values >= occupied_int) & (values <= 100)] = greys[OCCUPIED]
    return pixels


def scale_pixel_table(occupied_thresh: float, free_thresh: float) -> np.ndarray:
    """
    Return, for each value 0..100, a grey that scale mode loads back as that value.

    Raises ValueError when the thresholds are too close for 256 greys to hold 101 values.
    """
    greys = np.arange(256)
    loaded = pixels_to_cells(greys, 'scale', False, occupied_thresh, free_thresh)
    table = np.zeros(101, dtype=np.uint8)
    for value in range(101):
        matches = greys[loaded == value]
        if matches.size == 0:
            raise ValueError(f'scale mode cannot store the value {value} with thresholds '
                             f'free {free_thresh}, occupied {occupied_thresh}: too close')
        table[value] = matches[matches.size // 2]  # the middle of its band: robust
    table[0] = PIXEL_FREE if PIXEL_FREE in matches_of(loaded, 0) else table[0]
    table[100] = PIXEL_OCCUPIED if PIXEL_OCCUPIED in matches_of(loaded, 100) else table[100]
    return table


def matches_of(loaded: np.ndarray, value: int) -> np.ndarray:
    """Return the greys (indices of loaded) that load as value."""
    return np.flatnonzero(loaded == value)


def read_pgm(path: PathLike) -> np.ndarray:
    """
    Read an 8-bit PGM (P5 binary or P2 ASCII, maxval 255) as a uint8 array.

    Row 0 of the result is the image's TOP row (file order). Raises MapError naming the
    file when it is missing, not a PGM (PNG is recognised and refused), or malformed.
    """
    path = Path(path)
    if path.suffix.lower() == '.png':
        raise MapError(f'{path}: PNG images are not supported here; only PGM (P5/P2) is '
                       '(convert it, e.g. with `convert map.png map.pgm`)')
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise MapError(f'{path}: map image not found') from None
    except OSError as error:
        raise MapError(f'{path}: cannot read map image: {error.strerror or error}') from None
    if raw.startswith(_PNG_MAGIC):
        raise MapError(f'{path}: this is a PNG image; only PGM (P5/P2) is supported here')
    magic = raw[:2]
    if magic not in (b'P5', b'P2'):
        raise MapError(f'{path}: wrong magic {magic!r}: not an 8-bit greyscale PGM '
                       "(expected b'P5' or b'P2')")
    header, position = [], 2
    while len(header) < 3:
        token, position = _next_token(raw, position)
        if token is None:
            raise MapError(f'{path}: truncated PGM header (need width, height and maxval)')
        if not token.isdigit():
            raise MapError(f'{path}: bad PGM header value {token!r} (expected an integer)')
        header.append(int(token))
    width, height, maxval = header
    if width < 1 or height < 1:
        raise MapError(f'{path}: bad PGM size {width}x{height}')
    if maxval != 255:
        raise MapError(f'{path}: PGM maxval is {maxval}, not 255: only 8-bit images are '
                       'supported')
    count = width * height
    if magic == b'P5':
        if position >= len(raw) or raw[position] not in _WHITESPACE:
            raise MapError(f'{path}: truncated PGM: no pixel data after the header')
        data = raw[position + 1:position + 1 + count]
        if len(data) < count:
            raise MapError(f'{path}: truncated PGM: expected {count} pixel bytes '
                           f'({width}x{height}), found {len(data)}')
        pixels = np.frombuffer(data, dtype=np.uint8)
    else:
        values = []
        while len(values) < count:
            token, position = _next_token(raw, position)
            if token is None:
                raise MapError(f'{path}: truncated PGM: expected {count} pixel values '
                               f'({width}x{height}), found {len(values)}')
            if not token.isdigit() or int(token) > maxval:
                raise MapError(f'{path}: bad PGM pixel value {token!r} (expected 0..{maxval})')
            values.append(int(token))
        pixels = np.array(values, dtype=np.uint8)
    return pixels.reshape(height, width).copy()


def write_pgm(path: PathLike, pixels: np.ndarray) -> None:
    """Write a uint8 array as a binary P5 PGM with maxval 255; row 0 is the top row."""
    pixels = np.asarray(pixels)
    if pixels.ndim != 2 or pixels.size == 0:
        raise ValueError(f'pixels must be a non-empty 2-D array, not shape {pixels.shape}')
    if pixels.dtype != np.uint8:
        if pixels.min() < 0 or pixels.max() > 255:
            raise ValueError('pixel values must be in 0..255')
        pixels = pixels.astype(np.uint8)
    height, width = pixels.shape
    header = f'P5\n{width} {height}\n255\n'.encode('ascii')
    Path(path).write_bytes(header + np.ascontiguousarray(pixels).tobytes())


def _next_token(raw: bytes, position: int) -> Tuple[Optional[str], int]:
    """Return the next whitespace-separated PGM token and the position after it."""
    length = len(raw)
    while position < length:
        byte = raw[position]
        if byte in _WHITESPACE:
            position += 1
        elif byte == ord('#'):
            while position < length and raw[position] not in b'\r\n':
                position += 1
        else:
            break
    start = position
    while position < length and raw[position] not in _WHITESPACE and raw[position] != ord('#'):
        position += 1
    if start == position:
        return None, position
    return raw[start:position].decode('latin-1'), position


def _to_grid_frame(occupancy_map: OccupancyMap, x: float, y: float) -> Tuple[float, float]:
    """Return map-frame (x, y) relative to the grid origin, in the grid's own axes (m)."""
    origin_x, origin_y, yaw = occupancy_map.origin
    dx, dy = x - origin_x, y - origin_y
    if yaw == 0.0:
        return dx, dy
    cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
    return cos_yaw * dx + sin_yaw * dy, -sin_yaw * dx + cos_yaw * dy


def _is_number(value: object) -> bool:
    """Return True for int and float values (bool excluded)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _yaml_position(error: yaml.YAMLError) -> str:
    """Return ' at line L, column C: problem' for a YAML error that has a mark."""
    mark = getattr(error, 'problem_mark', None)
    problem = getattr(error, 'problem', None) or str(error)
    if mark is None:
        return f': {problem}'
    return f' at line {mark.line + 1}, column {mark.column + 1}: {problem}'


def find_map_file(text: str) -> Path:
    """
    Return the map YAML that text names: a path, ``package://PKG/relative/path``, or NAME.

    A package URL is looked up in the package's installed share directory (the source
    tree's package directory when it is not installed); a bare NAME (no '/' and no
    suffix) is ``maps/NAME.yaml`` of mecanum_map_server. Raises MapError if the package
    or file does not exist.
    """
    text = str(text).strip()
    if text.startswith('package://'):
        package, _, relative = text[len('package://'):].partition('/')
        if not package or not relative:
            raise MapError(f'{text!r}: expected package://PACKAGE/path/inside/its/share')
        path = _package_directory(package) / relative
    elif '/' not in text and not Path(text).suffix and text:
        path = _package_directory('mecanum_map_server') / 'maps' / f'{text}.yaml'
    else:
        path = Path(text).expanduser()
    if not path.is_file():
        raise MapError(f'{text!r}: no map file at {path}')
    return path


def _package_directory(package: str) -> Path:
    """Return a package's share directory, or its source directory when not installed."""
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory(package))
    except (ImportError, LookupError):
        source = Path(__file__).resolve().parents[2] / package
        if source.is_dir():
            return source
        raise MapError(f'package {package!r} not found (neither installed nor in {source.parent})')
