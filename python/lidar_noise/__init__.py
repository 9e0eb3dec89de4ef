"""lidar_noise: the lidar-noise Rust core on numpy point clouds.

Seeded, exact LiDAR noise (weather, dirty or damaged optics, sensor faults,
interference) configured by the same TOML chains as the ``lidar-noise`` command,
with the same option names, defaults, errors and random streams: a frame given the
same returns, configuration, seed and frame index gives the same bytes as
``lidar-noise run``, for any thread count.

This module only checks shapes and dtypes and lays numpy arrays out as columns;
every computation is the Rust library's (``_lidar_noise``), run with the GIL released.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any, Dict, List, NamedTuple, Optional, Sequence, Union

import numpy as np

from . import _lidar_noise as _core

__all__ = [
    "Chain",
    "Frame",
    "RETURN_DTYPE",
    "APPLIED_DTYPE",
    "POINT_DTYPE",
    "FATES",
    "read",
    "write",
    "points_to_returns",
    "ground",
    "cluster",
    "detect_objects",
    "sweep",
    "__version__",
]

__version__: str = _core.VERSION

#: Every field of a decoded return (``lidar_noise.read`` of a capture).
RETURN_DTYPE = np.dtype(
    [
        ("x", "<f4"),
        ("y", "<f4"),
        ("z", "<f4"),
        ("range", "<f4"),
        ("azimuth", "<f4"),
        ("elevation", "<f4"),
        ("time", "<f8"),
        ("packet", "<u4"),
        ("raw_distance", "<u2"),
        ("intensity", "u1"),
        ("laser", "u1"),
        ("ring", "u1"),
        ("block", "u1"),
        ("kind", "u1"),
    ],
    align=True,
)

#: What ``Chain.apply`` returns: the returns after the chain plus what happened to each.
APPLIED_DTYPE = np.dtype(
    [(n, RETURN_DTYPE[n]) for n in RETURN_DTYPE.names]
    + [
        ("range_clean", "<f4"),
        ("power", "<f8"),
        ("fate", "u1"),
        ("cause", "u1"),
        ("kept", "?"),
    ],
    align=True,
)

# Byte offset of every field of APPLIED_DTYPE, for the compiled side's record writer.
_APPLIED_LAYOUT = {n: APPLIED_DTYPE.fields[n][1] for n in APPLIED_DTYPE.names}
_APPLIED_LAYOUT["__itemsize__"] = APPLIED_DTYPE.itemsize

#: Plain points: x y z intensity ring (ring -1 where unknown).
POINT_DTYPE = np.dtype(
    [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("ring", "<i8")],
    align=True,
)

#: Fate codes, by value.
FATES = ("kept", "occluded", "below_power", "below_min_range", "replaced", "added")

def _sensor_model(sensor: Any) -> "tuple[str, int, List[float]]":
    """The model a ``sensor=`` name means (the command line's ``--sensor`` names: hdl32e,
    vlp16, puck-hi-res, vlp32c, hdl64e, hdl64e-s3; case, ``-`` and ``_`` ignored): its
    model name, laser count and per-laser elevations. ValueError listing the names for
    any other."""
    if not isinstance(sensor, str):
        raise ValueError(
            f"sensor {sensor!r}: give a sensor name such as \"hdl32e\" or \"hdl64e\""
        )
    return _core.sensor_model(sensor)


def _strided_ok(col: np.ndarray) -> np.ndarray:
    """``col`` itself when its stride is a whole number of items (the compiled side reads
    such views in place), else a contiguous copy (a packed record's field)."""
    if col.strides[0] % col.itemsize == 0 and col.ctypes.data % col.itemsize == 0:
        return col
    return np.ascontiguousarray(col)


def _field(arr: np.ndarray, name: str, dtype: np.dtype) -> np.ndarray:
    """Field ``name`` of a structured array as ``dtype`` (no copy when it already is and
    the layout allows)."""
    col = arr[name]
    if col.dtype == dtype:
        return _strided_ok(col)
    src, dst = col.dtype.kind, np.dtype(dtype).kind
    if src not in "biuf" or (src == "f" and dst in "iu"):
        raise ValueError(
            f"points: field `{name}` has dtype {col.dtype}, expected {np.dtype(dtype)}"
        )
    return col.astype(dtype)


def _whole_rings(ring: np.ndarray) -> np.ndarray:
    """Float ring values as integers, refusing NaN and fractions by point index."""
    if ring.dtype.kind in "iu":
        return ring.astype(np.int64, copy=False)
    bad = ~np.isfinite(ring) | (ring != np.round(ring))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"points: point {i} (0-based): ring {ring[i]} is not a whole number")
    return ring.astype(np.int64)


def _columns(points: Any, rows: bool = False) -> "tuple[str, Dict[str, np.ndarray]]":
    """Classifies ``points`` and lays it out as columns: ("returns", ...) for arrays with
    every field of a return, ("points", ...) for plain x y z intensity [ring]. With
    ``rows``, a C-ordered float32 (N, 4) or (N, 5) array is passed whole as ``rows``
    (for the compiled side's conversion to returns, which reads it row by row)."""
    if not isinstance(points, np.ndarray):
        raise ValueError(
            f"points: expected a numpy array, got {type(points).__name__}"
        )
    names = points.dtype.names
    if names is not None:
        if points.ndim != 1:
            raise ValueError(f"points: a structured array must be 1-D, not shape {points.shape}")
        if all(n in names for n in RETURN_DTYPE.names):
            return "returns", {n: _field(points, n, RETURN_DTYPE[n]) for n in RETURN_DTYPE.names}
        missing = [n for n in ("x", "y", "z") if n not in names]
        if missing:
            raise ValueError(
                f"points: field{'s' if len(missing) > 1 else ''} "
                f"{', '.join(missing)} missing (fields: {', '.join(names)})"
            )
        cols = {n: _field(points, n, np.float32) for n in ("x", "y", "z")}
        if "intensity" in names:
            cols["intensity"] = _field(points, "intensity", np.float32)
        else:
            cols["intensity"] = np.zeros(len(points), np.float32)
        if "ring" in names:
            ring = _whole_rings(points["ring"])
            if not (ring < 0).any():
                cols["ring"] = ring
            elif not (ring < 0).all():
                i = int(np.flatnonzero(ring < 0)[0])
                raise ValueError(f"points: point {i} (0-based): ring {ring[i]} is negative")
        if "time" in names:
            # Places the points by time, as `run` places a file's (see the guide's
            # "Other sensors").
            cols["time"] = _field(points, "time", np.float64)
        return "points", cols
    if points.ndim != 2 or points.shape[1] not in (4, 5):
        raise ValueError(
            f"points: expected an (N, 4) or (N, 5) array (x y z intensity [ring]) or a "
            f"structured array, got shape {points.shape}"
        )
    if points.dtype.kind != "f":
        raise ValueError(
            f"points: expected a float32 or float64 array, got dtype {points.dtype}"
        )
    if rows and points.dtype == np.float32 and points.flags.c_contiguous:
        return "points", {"rows": points}
    cols = {
        n: points[:, i].astype(np.float32, copy=False)
        for i, n in enumerate(("x", "y", "z", "intensity"))
    }
    if points.shape[1] == 5:
        # Checked (whole, in range, by point index) by the compiled side as it reads it.
        cols["ring"] = points[:, 4].astype(np.float32, copy=False)
    return "points", {n: _strided_ok(c) for n, c in cols.items()}


def _structured(cols: Dict[str, Any], dtype: np.dtype) -> np.ndarray:
    n = len(cols["x"])
    # Zeroed, not empty: the aligned dtypes have padding, which `tobytes` shows.
    out = np.zeros(n, dtype)
    for name in dtype.names:
        out[name] = cols[name]
    return out


class Frame(NamedTuple):
    """One frame of ``read``: its index in the capture (the index that keys the random
    streams: pass it as ``frame=``), whether it is a partial sweep, and its points."""

    index: int
    partial: bool
    points: np.ndarray
    #: Point-cloud files: how the intensity is scaled ("unit", "byte", "unstated").
    intensity_scale: Optional[str] = None
    #: Captures: the sensor told by the packets ("HDL-32E", "VLP-16", ...), a name
    #: ``Chain.from_toml(..., sensor=...)`` takes.
    sensor: Optional[str] = None


def _looks_like_capture(path: Path) -> bool:
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError:
        return False
    return head in (
        b"\xd4\xc3\xb2\xa1",
        b"\xa1\xb2\xc3\xd4",
        b"\x4d\x3c\xb2\xa1",
        b"\xa1\xb2\x3c\x4d",
        b"\x0a\x0d\x0d\x0a",
    )


def read(
    path: Union[str, "os.PathLike[str]"],
    sensor: Optional[str] = None,
    keep_partial: bool = False,
) -> List[Frame]:
    """Reads a capture (pcap/pcapng of an HDL-32E: its full sweeps, or every sweep with
    ``keep_partial``, as arrays of ``RETURN_DTYPE``) or a point-cloud file (KITTI .bin,
    nuScenes .pcd.bin, PCD, CSV: one frame of ``POINT_DTYPE``-like fields as stored).

    ``sensor`` names the sensor that recorded the file, any name ``Chain.from_toml``
    takes (ValueError for others). A point-cloud file's points are returned as stored
    whatever the sensor (place them on its firings with ``Chain.from_toml(...,
    sensor=...).apply``). A capture's sensor is told by its packets' structure (HDL-32E,
    VLP-16, Puck Hi-Res, VLP-32C, HDL-64E S2/S3, VLS-128) and given as each frame's
    ``sensor`` (a name ``Chain.from_toml`` takes); a ``sensor`` that names another is a
    ValueError.

    Raises OSError (FileNotFoundError) when the file cannot be read, ValueError when its
    content is malformed (the message names the file and the place)."""
    model = _sensor_model(sensor)[0] if sensor is not None else None
    p = Path(path)
    if _looks_like_capture(p):
        found, frames = _core.read_capture(p, keep_partial)
        if model is not None and model != found:
            raise ValueError(
                f"{p}: sensor {sensor!r}: the capture's packets are a {found}'s (told by "
                f"their structure); give sensor=None or the {found}"
            )
        return [
            Frame(i, partial, _structured(c, RETURN_DTYPE), None, found)
            for i, partial, c in frames
        ]
    if not p.exists():
        raise FileNotFoundError(f"{p}: No such file or directory")
    cols, _fmt, scale = _core.read_cloud(p)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")]
    if "ring" in cols:
        fields.append(("ring", "<i8"))
    if "time" in cols:
        fields.append(("time", "<f8"))
    return [Frame(0, False, _structured(cols, np.dtype(fields, align=True)), scale)]


def _atomic_write_bytes(path: Path, data: bytes) -> None:
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", dir=str(path.parent or Path(".")))
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def write(
    path: Union[str, "os.PathLike[str]"],
    points: np.ndarray,
    frame: int = 0,
    sensor: str = "hdl32e",
) -> None:
    """Writes ``points`` by the file's extension: ``.ply`` (binary PLY by the tool's own
    writer, with fate/cause/range_clean/power columns when present; plain points are
    first made returns of ``sensor``), ``.pcd.bin`` (nuScenes: float32 x y z intensity
    ring), ``.bin`` (KITTI: float32 x y z reflectance 0-1). Atomic: a failed write leaves
    nothing behind."""
    p = Path(path)
    name = p.name.lower()
    kind, cols = _columns(points)
    if name.endswith(".ply"):
        if kind == "points":
            cols, _order = points_to_returns(points, sensor=sensor, _raw=True)
        else:
            if points.dtype.names is not None:
                for extra, dt in (("range_clean", "<f4"), ("power", "<f8"), ("fate", "u1"), ("cause", "u1")):
                    if extra in points.dtype.names:
                        cols[extra] = _field(points, extra, np.dtype(dt))
        _core.write_ply(p, cols, frame)
        return
    if kind == "returns":
        intensity = cols["intensity"].astype(np.float32)
        ring = cols["ring"].astype(np.float32)
        byte_scale = True
    else:
        intensity = cols["intensity"]
        ring = cols.get("ring", np.zeros(len(intensity))).astype(np.float32)
        byte_scale = False
    if name.endswith(".pcd.bin"):
        table = np.stack([cols["x"], cols["y"], cols["z"], intensity, ring], axis=1)
    elif name.endswith(".bin"):
        refl = intensity / np.float32(255.0) if byte_scale else intensity
        table = np.stack([cols["x"], cols["y"], cols["z"], refl], axis=1)
    else:
        raise ValueError(f"{p}: unknown extension (write .ply, .bin or .pcd.bin)")
    _atomic_write_bytes(p, np.ascontiguousarray(table, dtype="<f4").tobytes())


def points_to_returns(
    points: np.ndarray,
    rotation_hz: float = 10.0,
    intensity_scale: str = "byte",
    sensor: str = "hdl32e",
    _raw: bool = False,
) -> "tuple[np.ndarray, np.ndarray]":
    """Plain points (x y z intensity [ring]) as returns of ``sensor`` (default the
    HDL-32E; any name ``Chain.from_toml`` takes), in firing order, and the input index of
    each (see the library's ``cloud::returns``). A ring, where given, is 0 (lowest beam)
    to the sensor's lasers - 1; a ``time`` field, where given, places the points on
    their firings by time rather than by azimuth."""
    _sensor_model(sensor)
    kind, cols = _columns(points, rows=True)
    if kind == "returns":
        raise ValueError("points: already returns (every field of a return is present)")
    out, order = _core.points_to_returns(cols, rotation_hz, intensity_scale, sensor)
    out.pop("moved")
    out.pop("shared")
    if _raw:
        return out, order
    return _structured(out, RETURN_DTYPE), order


class Chain:
    """A validated noise configuration (the TOML of ``lidar-noise run -c``) for frames
    of one sensor model (``sensor=``, the HDL-32E unless said)."""

    def __init__(self, core: Any) -> None:
        self._core = core

    @classmethod
    def from_toml(
        cls, text_or_path: Union[str, "os.PathLike[str]"], sensor: str = "hdl32e"
    ) -> "Chain":
        """Reads a configuration from TOML text or a file path, for frames of ``sensor``
        (the command line's ``--sensor`` names: "hdl32e", "vlp16", "puck-hi-res",
        "vlp32c", "hdl64e" (the S2, KITTI's), "hdl64e-s3"). The sensor's laser count
        sizes the chain's firings, bounds per-laser options and places plain points in
        ``apply``.

        Raises ValueError naming the key and line for an invalid configuration (the
        command line's message), for an unknown sensor (listing the names), and for
        per-laser options that do not fit the sensor (naming the stage and option, e.g.
        ``occlusion`` lasers = [40] on the HDL-32E); OSError when the file cannot be
        read."""
        _sensor_model(sensor)
        if isinstance(text_or_path, os.PathLike):
            return cls(_core.Chain.from_path(Path(text_or_path), sensor=sensor))
        if not isinstance(text_or_path, str):
            raise ValueError(
                f"config: expected TOML text or a path, got {type(text_or_path).__name__}"
            )
        looks_like_text = "\n" in text_or_path or "=" in text_or_path or text_or_path == ""
        if not looks_like_text:
            return cls(_core.Chain.from_path(Path(text_or_path), sensor=sensor))
        return cls(_core.Chain.from_text(text_or_path, sensor=sensor))

    @classmethod
    def from_dict(cls, config: Dict[str, Any], sensor: str = "hdl32e") -> "Chain":
        """Builds a configuration from a dict laid out as the TOML file (``noise`` a list
        of stage dicts), for frames of ``sensor`` (as ``from_toml``); the same names,
        defaults and errors as the TOML."""
        _sensor_model(sensor)
        if not isinstance(config, dict):
            raise ValueError(f"config: expected a dict, got {type(config).__name__}")
        return cls(_core.Chain.from_table(config, sensor=sensor))

    @property
    def sensor(self) -> str:
        """The model name of the sensor the chain is for ("HDL-32E", "HDL-64E S2", ...);
        ``sensor=`` takes it back."""
        return self._core.sensor

    @property
    def lasers(self) -> int:
        """Lasers of the sensor the chain is for (its rings are 0 to ``lasers - 1``)."""
        return self._core.lasers

    def validate(self) -> List[str]:
        """The configuration's warnings (the configuration was validated when read: an
        invalid one raised ValueError then)."""
        return list(self._core.warnings)

    @property
    def seed(self) -> int:
        """The configuration's seed (used when ``apply`` is given none)."""
        return self._core.seed

    @property
    def stages(self) -> List[str]:
        """The noise stages' types, in chain order."""
        return list(self._core.stages)

    @property
    def effective_toml(self) -> str:
        """The effective configuration (defaults filled in) as TOML."""
        return self._core.effective_toml

    def apply(
        self,
        points: np.ndarray,
        seed: Optional[int] = None,
        frame: int = 0,
        *,
        rotation_hz: float = 10.0,
        intensity_scale: str = "byte",
        threads: Optional[int] = None,
    ) -> np.ndarray:
        """Runs the chain and the detection filters on one frame.

        ``points``: a structured array with every field of ``RETURN_DTYPE`` (as ``read``
        gives a capture's frames: the result is exactly the command line's; laser ids
        below the sensor's lasers), or plain points, an (N, 4)/(N, 5) float array x y z
        intensity [ring] or a structured array with those names, each made a return of
        the chain's sensor (``points_to_returns``; a ring, where given, 0 to ``lasers -
        1``; ``rotation_hz`` places them on the firing grid, or a ``time`` field, where
        given, on their firings by time; ``intensity_scale`` "byte" for 0-255 or "unit"
        for 0-1).

        Returns an ``APPLIED_DTYPE`` array: row i is input point i (reported returns at
        their noisy position, dropped ones where they were), then the returns stages
        added (fate "added"); ``kept`` is the mask of returns the sensor reports.
        ``seed`` defaults to the configuration's; ``frame`` keys the random streams."""
        kind, cols = _columns(points, rows=True)
        if seed is not None and (not isinstance(seed, (int, np.integer)) or seed < 0):
            raise ValueError(f"seed {seed!r}: give a non-negative integer")
        if not isinstance(frame, (int, np.integer)) or not 0 <= frame < 2**32:
            raise ValueError(f"frame {frame!r}: give an integer from 0 to 2^32 - 1")
        # The compiled side writes the records' bytes straight into the array numpy
        # views as APPLIED_DTYPE (its field offsets passed along, so the two agree).
        if kind == "returns":
            out = self._core.apply_returns(cols, seed, int(frame), threads, _APPLIED_LAYOUT)
        else:
            out = self._core.apply_points(
                cols, seed, int(frame), float(rotation_hz), intensity_scale, threads,
                _APPLIED_LAYOUT,
            )
        return out.view(APPLIED_DTYPE)

    def detect(
        self, points: np.ndarray, seed: Optional[int] = None, frame: int = 0, noise: bool = True
    ) -> "tuple[np.ndarray, List[Dict[str, Any]]]":
        """The whole per-frame pipeline of ``run`` (noise unless ``noise=False``, ground,
        clusters, objects) on a frame of returns (plain points are made returns of the
        chain's sensor): the applied array with ``ground`` and ``cluster`` fields, and the
        clusters as ``clusters.json`` describes them."""
        import json

        cols = _returns_cols(points, self.sensor)
        out, clusters = self._core.detect(cols, seed, int(frame), noise)
        fields = [(n, APPLIED_DTYPE[n]) for n in APPLIED_DTYPE.names]
        dtype = np.dtype(fields + [("ground", "?"), ("cluster", "<i4")], align=True)
        return _structured(out, dtype), json.loads(clusters)

    def __repr__(self) -> str:
        return f"Chain(seed={self.seed}, stages={self.stages}, sensor={self.sensor!r})"


def _returns_cols(points: np.ndarray, sensor: str) -> Dict[str, np.ndarray]:
    kind, cols = _columns(points)
    if kind == "points":
        cols, _ = points_to_returns(points, sensor=sensor, _raw=True)
    return cols


def _config(section: str, options: Dict[str, Any], sensor: str = "hdl32e") -> Any:
    return _core.Chain.from_table({section: options}, sensor=sensor)


def ground(
    points: np.ndarray,
    method: str = "patchwork",
    seed: int = 0,
    frame: int = 0,
    sensor: str = "hdl32e",
    **options: Any,
) -> np.ndarray:
    """Ground labels (True = ground) by the pipeline's ground step: ``method``
    "patchwork", "range-image", "ransac" or "none", other ``[ground]`` keys as keyword
    arguments. Plain points are made returns of ``sensor`` first (default the HDL-32E;
    any name ``Chain.from_toml`` takes); the mask is in input order."""
    _sensor_model(sensor)
    kind, cols = _columns(points)
    order = None
    if kind == "points":
        cols, order = points_to_returns(points, sensor=sensor, _raw=True)
    core = _config("ground", {"method": method, **options}, sensor)
    labels = core.ground(cols, seed, int(frame))
    if order is None:
        return labels
    out = np.empty_like(labels)
    out[order] = labels
    return out


def cluster(points: np.ndarray, **options: Any) -> np.ndarray:
    """Cluster labels (-1 = noise) by the pipeline's clustering, ``[cluster]`` keys
    (``cutoff_m``, ``min_points``, ...) as keyword arguments; ``points`` any array with
    x y z (structured) or an (N, >=3) float array."""
    if isinstance(points, np.ndarray) and points.dtype.names is None:
        if points.ndim != 2 or points.shape[1] < 3 or points.dtype.kind != "f":
            raise ValueError(
                f"points: expected an (N, 3+) float array, got shape {points.shape} "
                f"dtype {points.dtype}"
            )
        cols = {n: points[:, i].astype(np.float32, copy=False) for i, n in enumerate("xyz")}
    else:
        _kind, cols = _columns(points)
    core = _config("cluster", options)
    labels, _n = core.cluster(cols)
    return labels


def detect_objects(
    points: np.ndarray,
    config: Optional[Chain] = None,
    seed: Optional[int] = None,
    frame: int = 0,
    noise: bool = False,
    sensor: Optional[str] = None,
) -> "tuple[np.ndarray, List[Dict[str, Any]]]":
    """Ground, clusters and objects of a frame by the pipeline of ``config`` (defaults
    when None), without the noise unless ``noise=True``; see ``Chain.detect``. Plain
    points are made returns of ``config``'s sensor, or of ``sensor`` when no ``config``
    is given (default the HDL-32E); a ``sensor`` other than ``config``'s is a
    ValueError (give it to ``Chain.from_toml``)."""
    if config is None:
        config = Chain.from_toml("", sensor=sensor if sensor is not None else "hdl32e")
    elif sensor is not None and _sensor_model(sensor)[0] != config.sensor:
        raise ValueError(
            f"sensor {sensor!r}: the configuration is for the {config.sensor} (give the "
            f"sensor to Chain.from_toml or Chain.from_dict)"
        )
    return config.detect(points, seed=seed, frame=frame, noise=noise)


def _parse_cell(text: str) -> Any:
    if text in ("true", "false"):
        return text == "true"
    if text == "":
        return None
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def sweep(
    captures: Union[str, "os.PathLike[str]", Sequence[Union[str, "os.PathLike[str]"]]],
    config: Optional[Union[str, "os.PathLike[str]"]] = None,
    vary: Optional[Dict[str, Sequence[Any]]] = None,
    seeds: Optional[str] = None,
    frames: Optional[str] = None,
    sets: Optional[Dict[str, Any]] = None,
    output: Optional[Union[str, "os.PathLike[str]"]] = None,
    as_dataframe: Optional[bool] = None,
) -> Any:
    """Runs what ``lidar-noise sweep`` runs (the library's plan and runner) and returns
    its tidy table (sweep.csv: one row per capture, frame, cell and seed) as a list of dicts, or a
    pandas DataFrame when pandas is importable (``as_dataframe=False`` forces the list).

    ``vary`` maps keys to values (``{"rain.rate_mm_h": [0, 3, 7]}`` is ``--vary
    rain.rate_mm_h=0,3,7``); ``seeds`` and ``frames`` as the command's (``"1..3"``);
    ``sets`` are ``--set`` overrides; ``output`` keeps the sweep's folder (index.html,
    plots), else a temporary one is removed. ValueError for bad options (the command's
    message), OSError for files."""
    import csv

    if isinstance(captures, (str, os.PathLike)):
        captures = [captures]
    paths = [str(Path(c)) for c in captures]
    varies = []
    for key, values in (vary or {}).items():
        if isinstance(values, (str, bytes)) or not isinstance(values, Sequence):
            values = [values]
        varies.append(f"{key}=" + ",".join(str(v) for v in values))
    overrides = [f"{key}={value}" for key, value in (sets or {}).items()]
    with tempfile.TemporaryDirectory(prefix="lidar-noise-sweep-") as tmp:
        folder = Path(output) if output is not None else Path(tmp) / "sweep"
        _core.sweep(
            paths,
            str(folder),
            config=str(Path(config)) if config is not None else None,
            varies=varies,
            sets=overrides,
            seeds=str(seeds) if seeds is not None else None,
            frames=str(frames) if frames is not None else None,
        )
        table = folder / "sweep.csv"
        if as_dataframe is not False:
            try:
                import pandas as pd  # type: ignore[import-not-found]
            except ImportError:
                if as_dataframe:
                    raise
            else:
                return pd.read_csv(table)
        with open(table, newline="") as f:
            return [{k: _parse_cell(v) for k, v in row.items()} for row in csv.DictReader(f)]
