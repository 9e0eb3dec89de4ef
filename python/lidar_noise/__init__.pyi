"""Type stubs of lidar_noise (the lidar-noise Rust core on numpy point clouds)."""

import os
from typing import Any, Dict, List, NamedTuple, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

#: Every field of a decoded return: x y z range azimuth elevation (float32), time
#: (float64, seconds past the hour), packet (uint32), raw_distance (uint16), intensity
#: laser ring block kind (uint8).
RETURN_DTYPE: np.dtype
#: RETURN_DTYPE plus range_clean (float32), power (float64, fraction of emitted power),
#: fate, cause (uint8; cause 255 = none or the detection filters) and kept (bool).
APPLIED_DTYPE: np.dtype
#: Plain points: x y z intensity (float32), ring (int64).
POINT_DTYPE: np.dtype
#: Fate names by code: kept, occluded, below_power, below_min_range, replaced, added.
FATES: Tuple[str, ...]

PathLike = Union[str, "os.PathLike[str]"]

class Frame(NamedTuple):
    """One frame of `read`: pass `index` as `frame=` to `Chain.apply`."""

    index: int
    partial: bool
    points: npt.NDArray[Any]
    intensity_scale: Optional[str] = ...
    sensor: Optional[str] = ...

class Chain:
    """A validated noise configuration (the TOML of `lidar-noise run -c`) for frames of
    one sensor model."""

    @classmethod
    def from_toml(cls, text_or_path: Union[str, "os.PathLike[str]"], sensor: str = "hdl32e") -> Chain:
        """TOML text or a file path, for frames of `sensor` ("hdl32e", "vlp16",
        "puck-hi-res", "vlp32c", "hdl64e", "hdl64e-s3"). ValueError (key and line) when
        invalid, for an unknown sensor, or for per-laser options that do not fit the
        sensor (stage and option named); OSError when the file cannot be read."""
    @classmethod
    def from_dict(cls, config: Dict[str, Any], sensor: str = "hdl32e") -> Chain:
        """A dict laid out as the TOML file (`noise`: a list of stage dicts), for frames
        of `sensor` (as `from_toml`)."""
    @property
    def sensor(self) -> str:
        """Model name of the chain's sensor ("HDL-32E", "HDL-64E S2", ...)."""
    @property
    def lasers(self) -> int:
        """Lasers of the chain's sensor (rings 0 to lasers - 1)."""
    def validate(self) -> List[str]:
        """The configuration's warnings (invalid configurations raise when read)."""
    @property
    def seed(self) -> int:
        """The configuration's seed."""
    @property
    def stages(self) -> List[str]:
        """Stage types in chain order."""
    @property
    def effective_toml(self) -> str:
        """The effective configuration as TOML."""
    def apply(
        self,
        points: npt.NDArray[Any],
        seed: Optional[int] = None,
        frame: int = 0,
        *,
        rotation_hz: float = 10.0,
        intensity_scale: str = "byte",
        threads: Optional[int] = None,
    ) -> npt.NDArray[Any]:
        """Noise and detection filters on one frame: RETURN_DTYPE arrays (as `read`
        gives, exact to the CLI) or plain (N, 4)/(N, 5) float / structured x y z
        intensity [ring] [time] points, placed on the chain's sensor's firings (by
        time where a time field is given). Returns
        APPLIED_DTYPE rows: input rows in order, then added returns. GIL released; the
        same bytes for any `threads`."""
    def detect(
        self,
        points: npt.NDArray[Any],
        seed: Optional[int] = None,
        frame: int = 0,
        noise: bool = True,
    ) -> Tuple[npt.NDArray[Any], List[Dict[str, Any]]]:
        """The run pipeline (noise, ground, clusters, objects): APPLIED_DTYPE plus
        `ground` (bool) and `cluster` (int32, -1 none), and the clusters' descriptions.
        Plain points are placed on the chain's sensor's firings."""

def read(path: PathLike, sensor: Optional[str] = None, keep_partial: bool = False) -> List[Frame]:
    """Frames of an HDL-32E capture (RETURN_DTYPE) or one frame of a point-cloud file
    (KITTI .bin, nuScenes .pcd.bin, PCD, CSV). `sensor`: any modelled name (ValueError
    for others); captures refuse all but "hdl32e". OSError / ValueError on bad files."""

def write(path: PathLike, points: npt.NDArray[Any], frame: int = 0, sensor: str = "hdl32e") -> None:
    """.ply (tool's writer, fate columns when present; plain points as returns of
    `sensor`), .pcd.bin, .bin; atomic."""

def points_to_returns(
    points: npt.NDArray[Any],
    rotation_hz: float = 10.0,
    intensity_scale: str = "byte",
    sensor: str = "hdl32e",
) -> Tuple[npt.NDArray[Any], npt.NDArray[np.uint32]]:
    """Plain points as returns of `sensor` in firing order, and each return's input
    index."""

def ground(
    points: npt.NDArray[Any],
    method: str = "patchwork",
    seed: int = 0,
    frame: int = 0,
    sensor: str = "hdl32e",
    **options: Any,
) -> npt.NDArray[np.bool_]:
    """Ground mask by the pipeline's ground step ("patchwork", "range-image", "ransac",
    "none"; other [ground] keys as keywords), in input order; plain points placed on
    `sensor`'s firings."""

def cluster(points: npt.NDArray[Any], **options: Any) -> npt.NDArray[np.int32]:
    """Cluster labels (-1 noise) by the pipeline's clustering ([cluster] keys as keywords)."""

def detect_objects(
    points: npt.NDArray[Any],
    config: Optional[Chain] = None,
    seed: Optional[int] = None,
    frame: int = 0,
    noise: bool = False,
    sensor: Optional[str] = None,
) -> Tuple[npt.NDArray[Any], List[Dict[str, Any]]]:
    """Ground, clusters and objects of a frame (no noise unless noise=True); plain
    points on `config`'s sensor, or `sensor`'s when no config is given."""

def sweep(
    captures: Union[PathLike, List[PathLike]],
    config: Optional[PathLike] = None,
    vary: Optional[Dict[str, Any]] = None,
    seeds: Optional[str] = None,
    frames: Optional[str] = None,
    sets: Optional[Dict[str, Any]] = None,
    output: Optional[PathLike] = None,
    as_dataframe: Optional[bool] = None,
) -> Any:
    """`lidar-noise sweep`'s tidy table (sweep.csv): a list of dicts, or a pandas
    DataFrame when pandas is installed (as_dataframe=False forces the list)."""
