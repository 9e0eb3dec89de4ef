"""The binding's input checks under mutated inputs (issue 30, "the fuzz harness covers ...
the Python binding's input checks"): a fixed number of inputs from a fixed seed, so the
result does not depend on the machine's speed. Every call either works or raises one of
Python's ordinary exceptions (ValueError, TypeError, OSError, KeyError, IndexError); a Rust
panic would surface as pyo3's PanicException, a BaseException that is not an Exception,
and a crash would end the interpreter."""

import numpy as np
import pytest

import lidar_noise as ln

ORDINARY = (ValueError, TypeError, OSError, KeyError, IndexError, OverflowError)
INPUTS = 400

SPECIAL = [np.nan, np.inf, -np.inf, 1e30, -1e30, 0.0, -0.0, 1e-40, 65536.0, -1.0, 0.5]


def mutated_points(rng):
    """An array of points with a random shape, dtype and special values."""
    n = int(rng.choice([0, 1, 2, 7, 300]))
    cols = int(rng.choice([0, 1, 3, 4, 5, 6]))
    dtype = rng.choice(["float32", "float64", "float16", "int32", "uint8", "bool", "object"])
    base = rng.uniform(-80, 80, size=(n, cols))
    if cols >= 4:
        base[:, 3] = rng.uniform(0, 255, n)
    if cols >= 5:
        base[:, 4] = rng.integers(0, 32, n)
    for _ in range(int(rng.integers(0, 4))):
        if n and cols:
            base[rng.integers(0, n), rng.integers(0, cols)] = rng.choice(SPECIAL)
    with np.errstate(all="ignore"):  # NaN and huge values cast to integers on purpose
        arr = base.astype(dtype)
    shape = rng.integers(0, 4)
    if shape == 1:
        arr = arr.reshape(-1)
    elif shape == 2 and arr.size:
        arr = arr[:, ::2]  # a non-contiguous view
    elif shape == 3:
        arr = arr.T
    return arr


def mutated_config(rng):
    """A small chain whose options get values of the wrong type or range."""
    values = [None, "x", -1, 0, 1e308, float("nan"), float("inf"), [], {}, True, 2**70, "300"]
    stage = rng.choice(
        [
            {"type": "fog", "visibility_m": 300.0},
            {"type": "rain", "rate_mm_h": 5.0},
            {"type": "snow", "preset": "moderate"},
            {"type": "occlusion", "lasers": [1, 2]},
        ]
    )
    stage = dict(stage)
    key = rng.choice(list(stage.keys()) + ["unknown_key"])
    if key != "type" and rng.random() < 0.8:
        stage[key] = values[int(rng.integers(0, len(values)))]
    config = {"seed": int(rng.integers(0, 2**31)), "noise": [stage]}
    if rng.random() < 0.2:
        config["seed"] = values[int(rng.integers(0, len(values)))]
    return config


def call(f):
    try:
        f()
    except ORDINARY:
        pass
    except Exception as e:  # noqa: BLE001 - any other Exception is a wrong kind of error
        pytest.fail(f"unexpected {type(e).__name__}: {e}")


def test_mutated_points_raise_ordinary_errors_or_run():
    rng = np.random.default_rng(30)
    chain = ln.Chain.from_dict({"seed": 1, "noise": [{"type": "rain", "rate_mm_h": 5.0}]})
    for _ in range(INPUTS):
        pts = mutated_points(rng)
        which = rng.integers(0, 4)
        if which == 0:
            call(lambda: chain.apply(pts, seed=int(rng.integers(0, 100)), frame=0))
        elif which == 1:
            call(lambda: ln.points_to_returns(pts))
        elif which == 2:
            call(lambda: ln.ground(pts))
        else:
            call(lambda: ln.cluster(pts))


def test_mutated_configs_raise_ordinary_errors_or_build():
    rng = np.random.default_rng(31)
    pts = np.zeros((10, 4), dtype=np.float32)
    pts[:, 0] = np.linspace(2, 40, 10)
    for _ in range(INPUTS):
        config = mutated_config(rng)

        def build_and_apply():
            chain = ln.Chain.from_dict(config)
            chain.apply(pts, frame=0)

        call(build_and_apply)


def test_mutated_seeds_and_frames_raise_ordinary_errors():
    rng = np.random.default_rng(32)
    chain = ln.Chain.from_dict({"seed": 1, "noise": []})
    pts = np.zeros((5, 4), dtype=np.float32)
    pts[:, 0] = 10.0
    odd = [-1, 2**64, 2**70, 1.5, "3", None, np.uint64(5), float("nan")]
    for _ in range(100):
        seed = odd[int(rng.integers(0, len(odd)))]
        frame = odd[int(rng.integers(0, len(odd)))]
        call(lambda: chain.apply(pts, seed=seed, frame=frame))
