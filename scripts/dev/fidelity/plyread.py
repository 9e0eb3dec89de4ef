"""Reads the PLY files lidar-noise writes (binary little-endian or ASCII), stdlib only.

read_ply(path) -> dict of column name -> list of values (one per vertex), in file order.
Used by the fidelity generator and by the reference-implementation runners, so both read
the tool's own output the same way.
"""
import struct

_TYPES = {"char": "b", "uchar": "B", "short": "h", "ushort": "H", "int": "i", "uint": "I",
          "float": "f", "double": "d", "int8": "b", "uint8": "B", "int16": "h",
          "uint16": "H", "int32": "i", "uint32": "I", "float32": "f", "float64": "d"}


def read_ply(path):
    """Columns of the `vertex` element of one PLY file as a dict name -> list."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    fmt = None
    count = 0
    props = []
    in_vertex = False
    for line in header:
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "format":
            fmt = parts[1]
        elif parts[0] == "element":
            in_vertex = parts[1] == "vertex"
            if in_vertex:
                count = int(parts[2])
        elif parts[0] == "property" and in_vertex:
            props.append((parts[2], parts[1]))
    names = [p[0] for p in props]
    if fmt == "ascii":
        rows = data[end:].decode("ascii").split("\n")[:count]
        cols = {n: [] for n in names}
        for row in rows:
            for (n, t), v in zip(props, row.split()):
                cols[n].append(float(v) if _TYPES[t] in "fd" else int(v))
        return cols
    if fmt != "binary_little_endian":
        raise ValueError(f"{path}: unsupported PLY format {fmt}")
    code = "<" + "".join(_TYPES[t] for _, t in props)
    size = struct.calcsize(code)
    body = data[end:end + size * count]
    values = list(zip(*struct.iter_unpack(code, body))) if count else [[] for _ in names]
    return {n: list(v) for n, v in zip(names, values)}
