"""Compares two Gaussian PLY files attribute by attribute (tests/splat_formats_test.sh).

Usage: compare_ply.py A.ply B.ply TOLERANCE [--match]
--match: B's splats may be in another order (splat-transform writes compressed PLY in Morton
order): each of A's splats is compared with B's nearest by position.
Reads binary little-endian PLYs (any scalar types), compares positions, log-scales, SH (f_dc, f_rest
present in both), opacity as sigmoid (so logits of +-inf, splat-transform's alpha 1 / 0, equal this
project's +-20) and quaternions up to sign (1 - |q.q'| of the normalised ones); prints the largest
difference per group and exits 1 when any exceeds TOLERANCE. Standard library only.
"""
import math
import struct
import sys

TYPES = {"float": "f", "float32": "f", "double": "d", "float64": "d", "uchar": "B", "uint8": "B", "char": "b",
         "int8": "b", "short": "h", "int16": "h", "ushort": "H", "uint16": "H", "int": "i", "int32": "i",
         "uint": "I", "uint32": "I"}


def read(path):
    data = open(path, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    count, props, in_vertex = 0, [], False
    for line in data[:end].decode().splitlines():
        w = line.split()
        if w and w[0] == "element":
            in_vertex = w[1] == "vertex"
            if in_vertex:
                count = int(w[2])
        elif w and w[0] == "property" and in_vertex:
            props.append((w[2], TYPES[w[1]]))
    row = struct.Struct("<" + "".join(t for _, t in props))
    columns = {name: [] for name, _ in props}
    for values in row.iter_unpack(data[end:end + row.size * count]):
        for (name, _), v in zip(props, values):
            columns[name].append(float(v))
    return columns


def reorder(a, b, cell=0.05):
    """B's columns reordered so that row i is the splat nearest to A's row i (a grid search)."""
    grid = {}
    for j, p in enumerate(zip(b["x"], b["y"], b["z"])):
        grid.setdefault(tuple(int(math.floor(c / cell)) for c in p), []).append(j)
    order = []
    for p in zip(a["x"], a["y"], a["z"]):
        key = [int(math.floor(c / cell)) for c in p]
        best, best_d = -1, math.inf
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    for j in grid.get((key[0] + dx, key[1] + dy, key[2] + dz), []):
                        d = (b["x"][j] - p[0]) ** 2 + (b["y"][j] - p[1]) ** 2 + (b["z"][j] - p[2]) ** 2
                        if d < best_d:
                            best, best_d = j, d
        assert best >= 0, f"no splat of B within {cell} of {p}"
        order.append(best)
    return {k: [v[j] for j in order] for k, v in b.items()}


def sigmoid(v):
    return 1 / (1 + math.exp(-max(-60.0, min(60.0, v))))


def main():
    a, b, tol = read(sys.argv[1]), read(sys.argv[2]), float(sys.argv[3])
    n = len(a["x"])
    assert len(b["x"]) == n, f"counts differ: {n} vs {len(b['x'])}"
    if "--match" in sys.argv:
        b = reorder(a, b)
    worst = {}

    def diff(group, xs, ys, f=lambda v: v):
        worst[group] = max([worst.get(group, 0.0)] + [abs(f(x) - f(y)) for x, y in zip(xs, ys)])

    for k in ("x", "y", "z"):
        diff("position", a[k], b[k])
    for k in ("scale_0", "scale_1", "scale_2"):
        if k in a and k in b:
            diff("log_scale", a[k], b[k])
    for k in a:
        if (k.startswith("f_dc_") or k.startswith("f_rest_")) and k in b:
            diff("sh", a[k], b[k])
    diff("opacity", a["opacity"], b["opacity"], sigmoid)
    rot = 0.0
    for i in range(n):
        qa = [a[f"rot_{k}"][i] for k in range(4)]
        qb = [b[f"rot_{k}"][i] for k in range(4)]
        na, nb = math.sqrt(sum(v * v for v in qa)), math.sqrt(sum(v * v for v in qb))
        rot = max(rot, 1 - abs(sum(x * y for x, y in zip(qa, qb))) / (na * nb))
    worst["rotation (1 - |q.q'|)"] = rot
    print(" ".join(f"{k}={v:.3g}" for k, v in worst.items()))
    sys.exit(0 if all(v <= tol for v in worst.values()) else 1)


if __name__ == "__main__":
    main()
