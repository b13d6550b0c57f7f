#!/usr/bin/env python3
"""oblique_rays.py: one pinhole camera's rays for `terrad trace` (little-endian float64
ox oy oz dx dy dz, one per pixel, row by row), for measuring steps per ray on an oblique view.
usage: oblique_rays.py X Y Z HEADING PITCH FOV W H > rays.bin  (dataset frame, degrees)"""
import math, struct, sys
x, y, z, heading, pitch, fov = map(float, sys.argv[1:7])
w, h = int(sys.argv[7]), int(sys.argv[8])
hd, p = math.radians(heading), math.radians(pitch)
f = (math.sin(hd) * math.cos(p), math.cos(hd) * math.cos(p), math.sin(p))
r = (math.cos(hd), -math.sin(hd), 0.0)
u = (-math.sin(p) * math.sin(hd), -math.sin(p) * math.cos(hd), math.cos(p))
k = math.tan(math.radians(fov) / 2)
out = bytearray()
for j in range(h):
    b = (1 - 2 * (j + 0.5) / h) * k * h / w
    for i in range(w):
        a = (2 * (i + 0.5) / w - 1) * k
        out += struct.pack('<6d', x, y, z, f[0] + a * r[0] + b * u[0],
                           f[1] + a * r[1] + b * u[1], f[2] + a * r[2] + b * u[2])
sys.stdout.buffer.write(out)
