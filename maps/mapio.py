"""ROS map_server map files: a PGM (or PNG) image plus a small YAML description.

Reading follows nav2_map_server ``map_io.cpp`` (``loadMapFromFile``): the pixel shade in [0, 1] is
``value / 255`` (mean of the colour channels), ``occ = 1 - shade`` (``shade`` if ``negate``), and the
``mode`` decides the cell value:

- ``trinary`` (default): ``occ > occupied_thresh`` -> 100, ``occ < free_thresh`` -> 0, else -1;
- ``scale``: like trinary but values in between are scaled linearly to 0..100, and transparent
  pixels are unknown;
- ``raw``: the grey value itself is the occupancy (0..100), anything else is unknown.

Image row 0 is the *top* of the map (largest y), so rows are flipped into grid order (row 0 at the
origin's y). Writing follows ``saveMapToFile`` in trinary mode: P5 PGM with 254 free, 0 occupied and
205 unknown, and the YAML that map_saver emits. The YAML parser handles the flat subset map files
use (scalars, quoted strings, comments, flow lists) so no YAML library is needed.
"""

from __future__ import annotations

import io
import math
import re
from dataclasses import dataclass
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from nav.types import GridGeometry, OccupancyGrid, Pose2D

DEFAULT_MAX_PIXELS = 64_000_000
MODES = ("trinary", "scale", "raw")

# map_saver's thresholding defaults (nav2_map_server map_saver.cpp: free_thresh_default 0.25,
# occupied_thresh_default 0.65), applied to the grid before writing.
SAVE_FREE_THRESH = 0.25
SAVE_OCCUPIED_THRESH = 0.65
# Thresholds written into a trinary YAML. Since navigation2 PR #5278 (2025, as ROS 1 did) they are
# fixed at 0.65 / 0.196 because trinary pixels are constants: with 0.25 the unknown grey 205
# (occ = 50/255 = 0.196) would reload as free.
YAML_OCCUPIED_THRESH = 0.65
YAML_FREE_THRESH = 0.196
PGM_FREE, PGM_OCCUPIED, PGM_UNKNOWN = 254, 0, 205


class MapFormatError(ValueError):
    """A map file is corrupt, truncated, too large or uses an unsupported option."""


@dataclass(frozen=True)
class MapMetadata:
    """The fields of a map YAML, with map_server's meaning. Unknown keys are kept in ``extra``."""

    image: str
    resolution: float
    origin: tuple[float, float, float]
    negate: bool = False
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196
    mode: str = "trinary"
    extra: tuple[tuple[str, object], ...] = ()

    def get(self, key: str, default: object = None) -> object:
        return dict(self.extra).get(key, default)


# ----------------------------------------------------------------------------------------- YAML


def _strip_comment(line: str) -> str:
    """Drop a ``#`` comment that is not inside quotes."""
    quote = ""
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = ""
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i]
    return line


def _scalar(text: str) -> object:
    text = text.strip()
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"":
        return text[1:-1]
    low = text.lower()
    if low in ("true", "yes", "on"):
        return True
    if low in ("false", "no", "off"):
        return False
    if low in ("null", "~", ""):
        return None
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def parse_map_yaml(text: str) -> dict[str, object]:
    """Parse the flat YAML subset used by map files: ``key: value`` lines, flow lists ``[a, b]``,
    block lists (``- a`` lines under a key), quotes and comments."""
    out: dict[str, object] = {}
    pending: str | None = None
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = _strip_comment(raw).rstrip()
        if not line.strip() or line.strip() in ("---", "..."):
            continue
        stripped = line.strip()
        if stripped.startswith("- ") and pending is not None:
            lst = out.setdefault(pending, [])
            if isinstance(lst, list):
                lst.append(_scalar(stripped[2:]))
            continue
        m = re.match(r"^\s*(['\"]?)([A-Za-z_][\w\-]*)\1\s*:(.*)$", line)
        if not m:
            raise MapFormatError(f"map YAML line {lineno}: cannot parse {raw.strip()!r}")
        key, value = m.group(2), m.group(3).strip()
        if value.startswith("["):
            if not value.endswith("]"):
                raise MapFormatError(f"map YAML line {lineno}: unterminated list for {key!r}")
            inner = value[1:-1].strip()
            out[key] = [_scalar(v) for v in inner.split(",")] if inner else []
            pending = None
        elif value == "":
            out[key] = []
            pending = key
        else:
            out[key] = _scalar(value)
            pending = None
    return out


def _number(data: dict[str, object], key: str, default: float | None = None) -> float:
    if key not in data:
        if default is None:
            raise MapFormatError(f"map YAML is missing required field {key!r}")
        return default
    v = data[key]
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise MapFormatError(f"map YAML field {key!r} must be a number, got {v!r}")
    return float(v)


def metadata_from_yaml(text: str) -> MapMetadata:
    """Validate a map YAML into ``MapMetadata`` (required: image, resolution, origin)."""
    data = parse_map_yaml(text)
    image = data.get("image")
    if not isinstance(image, str) or not image:
        raise MapFormatError("map YAML is missing required field 'image'")
    resolution = _number(data, "resolution")
    if resolution <= 0:
        raise MapFormatError(f"map YAML field 'resolution' must be positive, got {resolution}")
    origin = data.get("origin")
    if origin is None:
        raise MapFormatError("map YAML is missing required field 'origin'")
    if (
        not isinstance(origin, list)
        or len(origin) != 3
        or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in origin
        )
    ):
        raise MapFormatError(f"map YAML field 'origin' must be [x, y, yaw], got {origin!r}")
    negate = data.get("negate", 0)
    if negate not in (0, 1, True, False):
        raise MapFormatError(f"map YAML field 'negate' must be 0 or 1, got {negate!r}")
    occ = _number(data, "occupied_thresh", 0.65)
    free = _number(data, "free_thresh", 0.196)
    if not (0.0 <= free <= occ <= 1.0):
        raise MapFormatError(
            f"map YAML thresholds need 0 <= free_thresh ({free}) <= occupied_thresh ({occ}) <= 1"
        )
    mode = data.get("mode", "trinary")
    if mode not in MODES:
        raise MapFormatError(f"map YAML mode {mode!r} is not supported (use one of {', '.join(MODES)})")
    known = {"image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh", "mode"}
    extra = tuple((k, v) for k, v in data.items() if k not in known)
    return MapMetadata(
        image=image,
        resolution=resolution,
        origin=(float(origin[0]), float(origin[1]), float(origin[2])),
        negate=bool(negate),
        occupied_thresh=occ,
        free_thresh=free,
        mode=str(mode),
        extra=extra,
    )


# ---------------------------------------------------------------------------------------- images


def _pgm_tokens(data: bytes, count: int) -> tuple[list[int], int]:
    """Read ``count`` whitespace-separated integers of a PNM header (skipping comments)."""
    pos, out = 2, []
    n = len(data)
    while len(out) < count:
        while pos < n and data[pos : pos + 1].isspace():
            pos += 1
        if pos < n and data[pos : pos + 1] == b"#":
            while pos < n and data[pos : pos + 1] not in (b"\n", b"\r"):
                pos += 1
            continue
        start = pos
        while pos < n and data[pos : pos + 1].isdigit():
            pos += 1
        if start == pos:
            raise MapFormatError("PGM header is truncated or malformed")
        out.append(int(data[start:pos]))
    return out, pos


def decode_pgm(data: bytes, max_pixels: int = DEFAULT_MAX_PIXELS) -> np.ndarray:
    """Decode a binary (P5) or ASCII (P2) PGM into an (H, W) array of shades in [0, 1]."""
    magic = data[:2]
    if magic not in (b"P5", b"P2"):
        raise MapFormatError(f"not a PGM image (magic {magic!r}, expected P5 or P2)")
    (w, h, maxval), pos = _pgm_tokens(data, 3)
    if w <= 0 or h <= 0:
        raise MapFormatError(f"PGM has invalid size {w} x {h}")
    if w * h > max_pixels:
        raise MapFormatError(f"PGM is {w} x {h} = {w * h} pixels, more than the limit of {max_pixels}")
    if not 0 < maxval < 65536:
        raise MapFormatError(f"PGM maxval {maxval} out of range 1..65535")
    if magic == b"P5":
        pos += 1  # exactly one whitespace byte after maxval
        dtype = np.dtype(np.uint8) if maxval < 256 else np.dtype(">u2")
        need = w * h * dtype.itemsize
        body = data[pos : pos + need]
        if len(body) < need:
            raise MapFormatError(f"PGM pixel data truncated: {len(body)} of {need} bytes")
        pixels = np.frombuffer(body, dtype=dtype).reshape(h, w)
    else:
        try:
            values = np.array(data[pos:].split(), dtype=np.int64)
        except ValueError as exc:
            raise MapFormatError("ASCII PGM has non-numeric pixel data") from exc
        if values.size < w * h:
            raise MapFormatError(f"PGM pixel data truncated: {values.size} of {w * h} values")
        pixels = values[: w * h].reshape(h, w)
    if int(pixels.max(initial=0)) > maxval:
        raise MapFormatError(f"PGM has pixel values above maxval {maxval}")
    return pixels.astype(np.float64) / maxval


def decode_png(data: bytes, max_pixels: int = DEFAULT_MAX_PIXELS) -> tuple[np.ndarray, np.ndarray | None]:
    """Decode a PNG (via imageio) into shades in [0, 1] and an optional alpha mask (True = opaque)."""
    if len(data) >= 24 and data[:8] == b"\x89PNG\r\n\x1a\n":
        w, h = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
        if w <= 0 or h <= 0:
            raise MapFormatError(f"PNG has invalid size {w} x {h}")
        if w * h > max_pixels:
            raise MapFormatError(f"PNG is {w} x {h} = {w * h} pixels, more than the limit of {max_pixels}")
    else:
        raise MapFormatError("not a PNG image (bad signature)")
    try:
        img = np.asarray(iio.imread(io.BytesIO(data), extension=".png", plugin="pillow"))
    except Exception as exc:  # imageio raises many types for corrupt files
        raise MapFormatError(f"PNG could not be decoded: {exc}") from exc
    scale = 65535.0 if img.dtype == np.uint16 else 255.0
    alpha = None
    if img.ndim == 3:
        channels = img.shape[2]
        if channels in (2, 4):
            alpha = img[..., -1] >= scale
            img = img[..., :-1]
        img = img.astype(np.float64).mean(axis=2)
    return img.astype(np.float64) / scale, alpha


def decode_image(
    data: bytes, name: str, max_pixels: int = DEFAULT_MAX_PIXELS
) -> tuple[np.ndarray, np.ndarray | None]:
    """Decode a map image by content (PGM or PNG); ``name`` is only used in messages."""
    if data[:2] in (b"P5", b"P2"):
        return decode_pgm(data, max_pixels), None
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return decode_png(data, max_pixels)
    raise MapFormatError(f"map image {name!r} is neither PGM (P5/P2) nor PNG")


# ------------------------------------------------------------------------------------- conversion


def shades_to_occupancy(shade: np.ndarray, meta: MapMetadata, alpha: np.ndarray | None = None) -> np.ndarray:
    """Image shades (image row order) -> int8 occupancy in grid row order (flipped)."""
    occ = shade if meta.negate else 1.0 - shade
    if meta.mode == "raw":
        value = np.round(shade * 255.0)
        cells = np.where((value >= 0) & (value <= 100), value, -1)
    else:
        cells = np.full(shade.shape, -1.0)
        if meta.mode == "scale":
            span = max(meta.occupied_thresh - meta.free_thresh, 1e-12)
            cells = np.rint((occ - meta.free_thresh) / span * 100.0)
        cells = np.where(occ > meta.occupied_thresh, 100, cells)
        cells = np.where(occ < meta.free_thresh, 0, cells)
        if meta.mode == "scale" and alpha is not None:
            cells = np.where(alpha, cells, -1)
    return np.ascontiguousarray(np.flipud(cells).astype(np.int8))


def read_map_bytes(
    yaml_bytes: bytes, image_bytes: bytes, image_name: str = "", max_pixels: int = DEFAULT_MAX_PIXELS
) -> OccupancyGrid:
    """Build an OccupancyGrid from an uploaded YAML and its image."""
    try:
        text = yaml_bytes.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise MapFormatError("map YAML is not UTF-8 text") from exc
    meta = metadata_from_yaml(text)
    shade, alpha = decode_image(image_bytes, image_name or meta.image, max_pixels)
    data = shades_to_occupancy(shade, meta, alpha)
    h, w = data.shape
    geometry = GridGeometry(meta.resolution, w, h, Pose2D(*meta.origin))
    return OccupancyGrid(geometry, data)


def read_map_metadata(path: str | Path) -> MapMetadata:
    path = Path(path)
    try:
        return metadata_from_yaml(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise MapFormatError(f"cannot read map YAML {path}: {exc.strerror}") from exc
    except UnicodeDecodeError as exc:
        raise MapFormatError(f"map YAML {path} is not UTF-8 text") from exc


def load_map_yaml(path: str | Path, max_pixels: int = DEFAULT_MAX_PIXELS) -> OccupancyGrid:
    """Load a map_server map from its YAML file (the image path is relative to the YAML)."""
    path = Path(path)
    meta = read_map_metadata(path)
    image_path = Path(meta.image)
    if not image_path.is_absolute():
        image_path = path.parent / image_path
    try:
        image = image_path.read_bytes()
    except OSError as exc:
        raise MapFormatError(f"cannot read map image {image_path}: {exc.strerror}") from exc
    return read_map_bytes(path.read_bytes(), image, str(image_path), max_pixels)


# ----------------------------------------------------------------------------------------- writing


def _yaml_float(v: float) -> str:
    """Format like yaml-cpp does for map_saver (``0.05``, ``-10``, ``0``) without its 3-digit
    precision loss: integral values print without a decimal point, others with Python's shortest
    round-trip repr."""
    v = float(v)
    if v == 0.0:
        return "0"
    if v.is_integer() and abs(v) < 1e15:
        return str(int(v))
    return repr(v)


def encode_pgm(
    grid: OccupancyGrid, free_thresh: float = SAVE_FREE_THRESH, occupied_thresh: float = SAVE_OCCUPIED_THRESH
) -> bytes:
    """The P5 PGM map_saver writes in trinary mode (rows flipped so image row 0 is the top)."""
    free_i = int(np.rint(free_thresh * 100.0))
    occ_i = int(np.rint(occupied_thresh * 100.0))
    d = grid.data.astype(np.int16)
    pix = np.full(d.shape, PGM_UNKNOWN, dtype=np.uint8)
    known = (d >= 0) & (d <= 100)
    pix[known & (d <= free_i)] = PGM_FREE
    pix[known & (d >= occ_i)] = PGM_OCCUPIED
    g = grid.geometry
    header = f"P5\n# CREATOR: map_saver.cpp {g.resolution:.3f} m/pix\n{g.width} {g.height}\n255\n"
    return header.encode("ascii") + np.flipud(pix).tobytes()


def encode_yaml(grid: OccupancyGrid, image_name: str, extra: dict[str, object] | None = None) -> bytes:
    """The YAML map_saver writes in trinary mode; ``extra`` keys are appended
    (map_server ignores keys it does not know)."""
    o = grid.geometry.origin
    lines = [
        f"image: {image_name}",
        "mode: trinary",
        f"resolution: {_yaml_float(grid.geometry.resolution)}",
        f"origin: [{_yaml_float(o.x)}, {_yaml_float(o.y)}, {_yaml_float(o.theta)}]",
        "negate: 0",
        f"occupied_thresh: {_yaml_float(YAML_OCCUPIED_THRESH)}",
        f"free_thresh: {_yaml_float(YAML_FREE_THRESH)}",
    ]
    for k, v in (extra or {}).items():
        if isinstance(v, list | tuple):
            lines.append(f"{k}: [{', '.join(_yaml_float(x) for x in v)}]")
        else:
            lines.append(f"{k}: {v}")
    return ("\n".join(lines) + "\n").encode("utf-8")


def save_map(
    grid: OccupancyGrid, directory: str | Path, name: str = "map", extra: dict[str, object] | None = None
) -> Path:
    """Write ``<name>.pgm`` and ``<name>.yaml`` into ``directory`` as Nav2's map_saver does in
    trinary mode; returns the YAML path."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    (directory / f"{name}.pgm").write_bytes(encode_pgm(grid))
    yaml_path = directory / f"{name}.yaml"
    yaml_path.write_bytes(encode_yaml(grid, f"{name}.pgm", extra))
    return yaml_path
