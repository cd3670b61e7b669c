#!/usr/bin/env python3
"""Writes csv-clamp-motion.csv: 1 s at 100 Hz of a smooth clamp motion that starts
at the identity pose with zero velocity (every term is a (1 - cos)/2 ramp), a lift
and sway of a few millimetres plus a small twist about the bar's (x) axis.
Format t,tx,ty,tz,qw,qx,qy,qz (DESIGN.md, rotation about the world origin)."""
import math

rows = ["t,tx,ty,tz,qw,qx,qy,qz"]
for k in range(101):
    t = k / 100
    ramp = lambda f: 0.5 * (1 - math.cos(2 * math.pi * f * t))
    ty = 0.004 * ramp(2.0)
    tz = 0.006 * ramp(1.0)
    theta = 0.08 * ramp(1.5)  # rad, twist about x
    qw, qx = math.cos(theta / 2), math.sin(theta / 2)
    rows.append(f"{t:.2f},0,{ty:.9f},{tz:.9f},{qw:.12f},{qx:.12f},0,0")
with open("csv-clamp-motion.csv", "w") as f:
    f.write("\n".join(rows) + "\n")
