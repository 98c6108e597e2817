"""Writes a random 3DGS PLY (Inria layout, SH degree 3) for tests/splat_formats_test.sh.
Usage: random_3dgs.py OUT.ply N SEED. Some splats are fully opaque or transparent (alpha 1 / 0 after
8-bit quantisation), as real captures have. Standard library only."""
import math
import random
import struct
import sys

out, n, seed = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
rng = random.Random(seed)
names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"] + [f"f_rest_{i}" for i in range(45)] + \
    ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
rows = []
for i in range(n):
    q = [rng.gauss(0, 1) for _ in range(4)]
    norm = math.sqrt(sum(v * v for v in q))
    opacity = 12.0 if i < n // 20 else -12.0 if i < n // 10 else rng.gauss(0, 2)
    rows.append([rng.gauss(0, 1.5) for _ in range(3)] + [0, 0, 0] + [rng.gauss(0, 0.8) for _ in range(3)] +
                [rng.gauss(0, 0.15) for _ in range(45)] + [opacity] + [rng.gauss(-4, 0.7) for _ in range(3)] +
                [v / norm for v in q])
header = "ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % n + "".join(f"property float {k}\n" for k in names) + "end_header\n"
with open(out, "wb") as f:
    f.write(header.encode())
    row = struct.Struct("<%df" % len(names))
    for r in rows:
        f.write(row.pack(*r))
