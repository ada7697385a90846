#!/usr/bin/env python3
"""Writes scenarios/maps/warehouse.{pgm,yaml}: a 12 x 9 m warehouse floor as map_saver would
save it (0.05 m cells, 254 free, 0 occupied, 205 unknown outside the walls).

Run from the repository root: python3 tools/make_maps.py
"""

RES = 0.05
W, H = 12.0, 9.0
MARGIN = 0.5  # unknown space around the building
ORIGIN = (-W / 2 - MARGIN, -H / 2 - MARGIN)
NX, NY = int(round((W + 2 * MARGIN) / RES)), int(round((H + 2 * MARGIN) / RES))
FREE, OCC, UNKNOWN = 254, 0, 205

img = [[UNKNOWN] * NX for _ in range(NY)]  # row 0 = top (max y)


def fill(x0, y0, x1, y1, v):
    """World-frame rectangle [x0, x1] x [y0, y1]."""
    for j in range(NY):
        y = ORIGIN[1] + (NY - 1 - j + 0.5) * RES
        if not (y0 <= y <= y1):
            continue
        for i in range(NX):
            x = ORIGIN[0] + (i + 0.5) * RES
            if x0 <= x <= x1:
                img[j][i] = v


t = 0.15  # wall thickness
fill(-W / 2, -H / 2, W / 2, H / 2, OCC)
fill(-W / 2 + t, -H / 2 + t, W / 2 - t, H / 2 - t, FREE)
# An office in the north-west corner with a 1 m door.
fill(-6.0, 1.5, -2.5, 1.5 + t, OCC)
fill(-2.5 - t, 1.5, -2.5, 4.5, OCC)
fill(-4.2, 1.5, -3.2, 1.5 + t, FREE)
# Shelving rows (0.6 m deep, 3.2 m long) with 1.4 m aisles.
for k in range(4):
    x = -0.5 + k * 1.6
    fill(x, -3.0, x + 0.6, 0.2, OCC)
# Pillars.
for (px, py) in [(-3.0, -1.5), (-3.0, -3.5), (2.0, 2.6), (-1.0, 2.6)]:
    fill(px - 0.15, py - 0.15, px + 0.15, py + 0.15, OCC)
# A pallet stack and a desk inside the office.
fill(-5.2, -4.3, -4.2, -3.5, OCC)
fill(-5.4, 3.2, -4.4, 3.8, OCC)

with open("scenarios/maps/warehouse.pgm", "wb") as f:
    f.write(b"P5\n# rlnav warehouse map (tools/make_maps.py)\n%d %d\n255\n" % (NX, NY))
    for row in img:
        f.write(bytes(row))
with open("scenarios/maps/warehouse.yaml", "w") as f:
    f.write(
        "# A 12 x 9 m warehouse floor in the ROS map_server format (tools/make_maps.py writes it).\n"
        "image: warehouse.pgm\n"
        f"resolution: {RES}\n"
        f"origin: [{ORIGIN[0]}, {ORIGIN[1]}, 0.0]\n"
        "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\nmode: trinary\n"
    )
