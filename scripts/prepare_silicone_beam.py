#!/usr/bin/env python3
"""Turns the real silicone-beam captures (srl-ethz/diffPD_sim2real, commit 825e7b7,
MIT) into kelvin's marker files for yaml/examples/silicone-beam-*.yaml, and compares
a kelvin simulation with them.

  scripts/prepare_silicone_beam.py [DATA_DIR] [--case NAME ...] [--outdir DIR] [--duration S]
  scripts/prepare_silicone_beam.py [DATA_DIR] --case NAME --compare SIMULATED.csv

Input: the captures in kelvin's wide marker CSV (t,Name_x,Name_y,Name_z,...; m, s;
empty = occluded) in DATA_DIR (default /work/shared/data/real/silicone-beam; the
repository's python/.../Measurement_data/*.c3d, converted), one per case (default:
all three):

  gravity   beam_gravity_V2_a.csv   released under gravity alone
  load52    beam_load52_V2_a.csv    released with 52 g hung at the free end
  load101   beam_load101_V2_a.csv   released with 101 g hung at the free end

Outputs, in --outdir (default yaml/examples/silicone-beam next to this script's repo),
for each case (SUFFIX is empty for gravity, -load52, -load101):

  observed{SUFFIX}.csv  t,Tip_-_1_x,...: the three Tip markers' tracks in the model
                        frame, t = 0 at that capture's release, --duration seconds of it
                        (default 1.5 s; less if the capture ends sooner)
  markers.csv           name,x,y,z: the rest positions of the three Tip markers in the
                        model frame (the points of the beam's surface they are attached
                        to, see 4.), from the gravity capture. A load case's tracks are
                        translated onto these when its own registered rest positions lie
                        within SHARED_REST (0.5 mm) of them; otherwise the case gets its
                        own markers{SUFFIX}.csv (printed, with the differences).

Each case goes through the same steps (standard library only; every estimate is
printed):

 1. Still frames. The tip is still at the start; its centroid's scatter over the first
    0.5 s (or up to 0.1 s before it has first moved 1 mm, when that is earlier) is the
    noise level. The first frame where it has moved more than 0.2 mm from its still
    position marks the motion; every frame 20 ms or more before that is a pre-release
    rest frame.
 2. Release time. Released from rest and undeformed, every point of the beam starts
    falling with the acceleration of gravity, so the tip's displacement grows as
    ½ a (t − t₀)² for the first ~25 ms. A straight-line fit of sqrt(displacement)
    against t over the first frames with 0.02 mm < displacement < 3 mm gives t₀ and a
    (a close to 9.81 m/s² checks the estimate); the tip's height around t₀ is printed
    next to the free fall from t₀.
 3. Registration (capture frame -> model frame, rigid). The model is a box
    [0, 0.1] × [0, 0.03] × [0, 0.03] m clamped at x = 0, gravity along −z (so the top
    face is z = 0.03). The six markers' mean pre-release positions are fitted (least
    squares, Horn's quaternion method) to where the diffPD_sim2real code places them on
    its beam (python/.../Environments/beam_env.py, `target_points`, their frame shifted
    by +0.1 m in x so that the clamp face is at x = 0):
      Tip 1 (0.1, 0.015, 0.036)   6 mm above the top face, at the end-face plane
      Tip 2 (0.1, −0.006, 0.024)  6 mm beside the side face y = 0
      Tip 3 (0.1, 0.036, 0.006)   6 mm beside the side face y = 0.03
      Base 1..3 (0.006, −0.01, −0.001), (0.006, 0.04, 0.0275), (0.006, 0.04, 0)
                (on the clamp, they do not move with the beam)
    The pairwise distances of the captured markers match this layout to within about
    a millimetre; the residuals of the fit are printed. Two independent checks follow:
    the beam axis from the Base centroid to the Tip centroid, and the direction of
    gravity as the settled tip displacement (last second of the capture)
    orthogonalised against the axis, are compared with the registered model +x and −z.
    The roll about the beam axis is then set so that the settled drop has no sideways
    component.
 4. Attachment. The Tip markers are balls about 6 mm off the beam's surface; kelvin
    attaches a marker outside the mesh to the nearest surface point and then moves it
    exactly with that point, so a marker written at the ball's position would keep a
    constant ~6 mm offset that no material parameter can remove. Each marker's rest
    position is therefore replaced by its nearest point on the box (coordinates clamped
    to the box), and its whole track is translated by the same constant vector. What
    remains unmodelled is the ball's lever arm: the end face rotates by ~0.08 rad, which
    moves Tip 1 (6 mm above the top face) about 0.5 mm further along the beam than its
    surface point; Tips 2 and 3 sit beside the neutral plane and are hardly affected.
 5. Output. Frames from the release on, at their capture times shifted by −t₀, after a
    first row at t = 0 holding the rest positions (the beam is at rest until t₀).

--compare SIMULATED.csv (the markers.csv of `kelvin simulate`, same marker names)
prints the simulation's RMS distance from the case's observed tracks (per marker and
overall; the simulated positions are interpolated to the observed times with cubic
Hermite curves), the settled sag (tip centroid's mean drop over the last second of
the capture, and of the simulation when it runs longer than the observation) and the
period of the ringing, observed and simulated.
"""
import argparse
import contextlib
import csv
import io
import math
import os
import sys

TIP = ["Tip_-_1", "Tip_-_2", "Tip_-_3"]
BASE = ["Base_-_1", "Base_-_2", "Base_-_3"]
# Model-frame positions of the markers (m), from diffPD_sim2real's beam_env.py, x + 0.1.
LAYOUT = {
    "Tip_-_1": (0.1, 0.015, 0.036),
    "Tip_-_2": (0.1, -0.006, 0.024),
    "Tip_-_3": (0.1, 0.036, 0.006),
    "Base_-_1": (0.006, -0.01, -0.001),
    "Base_-_2": (0.006, 0.04, 0.0275),
    "Base_-_3": (0.006, 0.04, 0.0),
}
BOX_LO = (0.0, 0.0, 0.0)
BOX_HI = (0.1, 0.03, 0.03)
G = 9.81


# --- small vector helpers -------------------------------------------------------------
def add(a, b):
    return tuple(x + y for x, y in zip(a, b))


def sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def scale(a, s):
    return tuple(x * s for x in a)


def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def norm(a):
    return math.sqrt(dot(a, a))


def unit(a):
    return scale(a, 1.0 / norm(a))


def mean(points):
    n = len(points)
    return tuple(sum(p[k] for p in points) / n for k in range(3))


def matvec(m, v):
    return tuple(dot(row, v) for row in m)


def angle_deg(a, b):
    c = max(-1.0, min(1.0, dot(unit(a), unit(b))))
    return math.degrees(math.acos(c))


def jacobi_eigen(a):
    """Eigenvalues and eigenvectors (columns) of a small symmetric matrix."""
    n = len(a)
    a = [row[:] for row in a]
    v = [[float(i == j) for j in range(n)] for i in range(n)]
    for _ in range(100):
        off = sum(a[i][j] ** 2 for i in range(n) for j in range(n) if i != j)
        if off < 1e-30:
            break
        for p in range(n):
            for q in range(p + 1, n):
                if abs(a[p][q]) < 1e-300:
                    continue
                theta = (a[q][q] - a[p][p]) / (2 * a[p][q])
                t = math.copysign(1.0, theta) / (abs(theta) + math.sqrt(theta * theta + 1))
                c = 1 / math.sqrt(t * t + 1)
                s = t * c
                for k in range(n):
                    akp, akq = a[k][p], a[k][q]
                    a[k][p], a[k][q] = c * akp - s * akq, s * akp + c * akq
                for k in range(n):
                    apk, aqk = a[p][k], a[q][k]
                    a[p][k], a[q][k] = c * apk - s * aqk, s * apk + c * aqk
                for k in range(n):
                    vkp, vkq = v[k][p], v[k][q]
                    v[k][p], v[k][q] = c * vkp - s * vkq, s * vkp + c * vkq
    return [a[i][i] for i in range(n)], v


def rigid_fit(src, dst):
    """R, t minimising Σ |R src_i + t − dst_i|² (Horn 1987, unit quaternions)."""
    cs, cd = mean(src), mean(dst)
    S = [[0.0] * 3 for _ in range(3)]
    for p, q in zip(src, dst):
        p, q = sub(p, cs), sub(q, cd)
        for i in range(3):
            for j in range(3):
                S[i][j] += p[i] * q[j]
    (sxx, sxy, sxz), (syx, syy, syz), (szx, szy, szz) = S
    N = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ]
    values, vectors = jacobi_eigen(N)
    k = max(range(4), key=lambda i: values[i])
    w, x, y, z = (vectors[r][k] for r in range(4))
    R = [
        [w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z],
    ]
    return R, sub(cd, matvec(R, cs))


# --- the steps --------------------------------------------------------------------------
CASES = {  # name: (capture file, suffix of the output files)
    "gravity": ("beam_gravity_V2_a.csv", ""),
    "load52": ("beam_load52_V2_a.csv", "-load52"),
    "load101": ("beam_load101_V2_a.csv", "-load101"),
}
SHARED_REST = 0.5e-3  # m: a case shares markers.csv when its rest points lie this close


def read_capture(path, required=TIP + BASE):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header = rows[0]
    if header[0] != "t" or (len(header) - 1) % 3:
        sys.exit(f"{path}: expected a header t,Name_x,Name_y,Name_z,...")
    names = [header[i][:-2] for i in range(1, len(header), 3)]
    times, tracks = [], {n: [] for n in names}
    for row in rows[1:]:
        if not row:
            continue
        times.append(float(row[0]))
        for j, n in enumerate(names):
            cells = row[1 + 3 * j : 4 + 3 * j]
            tracks[n].append(None if "" in cells or "nan" in cells else tuple(float(c) for c in cells))
    for n in required:
        if n not in tracks:
            sys.exit(f"{path}: no marker '{n}'")
    return times, tracks


def read_rest(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return {r[0]: tuple(float(c) for c in r[1:4]) for r in rows[1:] if r}


def tip_centroid(tracks, k):
    points = [tracks[n][k] for n in TIP]
    return None if None in points else mean(points)


def mean_position(tracks, name, frames):
    points = [tracks[name][k] for k in frames if tracks[name][k] is not None]
    return mean(points)


def print_residuals(residuals, notes=None):
    """Prints, for each marker, the RMS length of its residual vectors (mm) and their
    mean (x, y, z), after notes[marker] when given; returns the overall RMS in mm."""
    sq, count = 0.0, 0
    for m, vectors in residuals.items():
        m_sq = sum(dot(r, r) for r in vectors)
        sq, count = sq + m_sq, count + len(vectors)
        r = mean(vectors)
        lead = f"{notes[m]}     " if notes else "residual "
        print(f"  {m:9s}  {lead}{1e3 * math.sqrt(m_sq / len(vectors)):6.3f} mm "
              f"({1e3 * r[0]:+.2f}, {1e3 * r[1]:+.2f}, {1e3 * r[2]:+.2f})")
    return 1e3 * math.sqrt(sq / count)


def layout_residuals(names, rest, to_model):
    return {m: [sub(to_model(rest[m]), LAYOUT[m])] for m in names}


def prepare(path):
    """Steps 1–4 on one capture; returns what the outputs and --compare need."""
    times, tracks = read_capture(path)
    n = len(times)
    rate = (n - 1) / (times[-1] - times[0])
    print(f"capture: {path}: {n} frames, {rate:.1f} Hz, {times[-1] - times[0]:.2f} s")

    # 1. Still frames and the onset of motion.
    start = tip_centroid(tracks, 0)
    moved = next(k for k in range(n) if tip_centroid(tracks, k) is not None
                 and norm(sub(tip_centroid(tracks, k), start)) > 1e-3)
    window = min(0.5, times[moved] - times[0] - 0.1)
    first = [k for k in range(n) if times[k] - times[0] <= window]
    still = mean([tip_centroid(tracks, k) for k in first])
    noise = math.sqrt(sum(norm(sub(tip_centroid(tracks, k), still)) ** 2 for k in first) / len(first))
    disp = [None if tip_centroid(tracks, k) is None else norm(sub(tip_centroid(tracks, k), still))
            for k in range(n)]
    onset = next(k for k in range(n) if disp[k] is not None and disp[k] > 2e-4)
    rest_frames = [k for k in range(n) if times[k] <= times[onset] - 0.02]
    print(f"still tip: scatter {1e3 * noise:.4f} mm RMS over the first {window:.2f} s; "
          f"moved > 0.2 mm first at t = {times[onset]:.3f} s")

    # 2. Release time: sqrt(d) = sqrt(a/2) (t − t0) on the first frames of the fall.
    fall = [k for k in range(rest_frames[-1], n) if disp[k] is not None and 2e-5 < disp[k] < 3e-3]
    fall = [k for k in fall if k <= onset + 2]
    xs, ys = [times[k] for k in fall], [math.sqrt(disp[k]) for k in fall]
    xm, ym = sum(xs) / len(xs), sum(ys) / len(ys)
    slope = sum((x - xm) * (y - ym) for x, y in zip(xs, ys)) / sum((x - xm) ** 2 for x in xs)
    t0 = xm - ym / slope
    accel = 2 * slope * slope
    print(f"release: t0 = {t0:.4f} s (from {len(fall)} frames, t = "
          f"{', '.join(f'{x:.2f}' for x in xs)} s; initial acceleration {accel:.2f} m/s², "
          f"free fall would be {G})")
    if not times[rest_frames[-1]] < t0 < times[onset]:
        sys.exit("release time outside the frames around the onset of motion")
    print(f"rest frames: {len(rest_frames)} (t = {times[rest_frames[0]]:.2f} … "
          f"{times[rest_frames[-1]]:.2f} s)")

    # 3. Registration.
    names = TIP + BASE
    rest = {m: mean_position(tracks, m, rest_frames) for m in names}
    scatter = {m: math.sqrt(sum(norm(sub(tracks[m][k], rest[m])) ** 2 for k in rest_frames
                                if tracks[m][k] is not None) / len(rest_frames)) for m in names}
    R, t = rigid_fit([rest[m] for m in names], [LAYOUT[m] for m in names])
    to_model = lambda p: add(matvec(R, p), t)  # noqa: E731
    print("rigid fit of the six markers to the layout:")
    print("  marker     rest scatter   residual |model − layout| (mm)")
    rms = print_residuals(layout_residuals(names, rest, to_model),
                          {m: f"{1e3 * scatter[m]:6.3f} mm" for m in names})
    print(f"  RMS residual {rms:.3f} mm")

    # Checks of the registration against the data themselves.
    settled_frames = [k for k in range(n) if times[k] >= times[-1] - 1.0]
    settled = {m: mean_position(tracks, m, settled_frames) for m in TIP}
    line = sub(mean([rest[m] for m in TIP]), mean([rest[m] for m in BASE]))
    layout_line = sub(mean([LAYOUT[m] for m in TIP]), mean([LAYOUT[m] for m in BASE]))
    print(f"Base -> Tip centroid line: {angle_deg(matvec(R, line), (1, 0, 0)):.2f}° from the "
          f"beam axis (model +x); in the layout itself it is {angle_deg(layout_line, (1, 0, 0)):.2f}° "
          f"(the Base markers sit lower and to one side), so it is not the beam axis")
    drop = mean([sub(settled[m], rest[m]) for m in TIP])
    dm = matvec(R, drop)
    print(f"settled tip drop (mean of t >= {times[settled_frames[0]]:.2f} s), model frame: "
          f"({1e3 * dm[0]:+.3f}, {1e3 * dm[1]:+.3f}, {1e3 * dm[2]:+.3f}) mm, "
          f"{1e3 * norm(dm):.3f} mm long")

    # Roll about the beam axis. The layout fixes it only to a few degrees (residuals of
    # ~1 mm at ~20 mm from the axis); the settled drop fixes it better: the beam bends in
    # the plane of gravity, so its sideways (y) component must vanish. Rotate about the
    # centre line (y = z = 0.015) by the angle that removes it; pitch and yaw stay as
    # fitted (the end face's rotation moves the markers along x, see README.md).
    psi = -math.atan2(dm[1], -dm[2])
    c, s = math.cos(psi), math.sin(psi)
    Rx = [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]
    centre = (0.0, 0.5 * (BOX_LO[1] + BOX_HI[1]), 0.5 * (BOX_LO[2] + BOX_HI[2]))
    R = [[sum(Rx[i][k] * R[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
    t = add(matvec(Rx, sub(t, centre)), centre)
    to_model = lambda p: add(matvec(R, p), t)  # noqa: E731
    dm = matvec(R, drop)
    print(f"roll about the beam axis: {math.degrees(psi):+.2f}°; settled drop now "
          f"({1e3 * dm[0]:+.3f}, {1e3 * dm[1]:+.3f}, {1e3 * dm[2]:+.3f}) mm; gravity is model −z")
    rms = print_residuals(layout_residuals(names, rest, to_model))
    print(f"  RMS residual after the roll {rms:.3f} mm")
    print("final registration (capture -> model): x_model = R x_capture + t, rows of R:")
    for row in R:
        print(f"  [{row[0]:+.6f} {row[1]:+.6f} {row[2]:+.6f}]")
    print(f"  t = [{t[0]:+.6f} {t[1]:+.6f} {t[2]:+.6f}] m")

    # The release, seen in the model frame: the tip centroid's height against free fall.
    rest_z = to_model(mean([rest[m] for m in TIP]))[2]
    print("tip centroid height around the release (model frame, relative to rest; "
          "free fall from t0 for comparison):")
    for k in range(n):
        if -0.035 < times[k] - t0 < 0.075 and tip_centroid(tracks, k) is not None:
            dz = to_model(tip_centroid(tracks, k))[2] - rest_z
            ff = -0.5 * G * max(0.0, times[k] - t0) ** 2
            print(f"  t − t0 = {1e3 * (times[k] - t0):+6.1f} ms: z {1e3 * dz:+8.3f} mm, "
                  f"free fall {1e3 * ff:+8.3f} mm")

    # 4. Attachment points on the box surface.
    attached = {}
    for m in TIP:
        p = to_model(rest[m])
        attached[m] = tuple(min(max(p[k], BOX_LO[k]), BOX_HI[k]) for k in range(3))
        q = attached[m]
        print(f"{m}: ball at ({1e3 * p[0]:.2f}, {1e3 * p[1]:.2f}, {1e3 * p[2]:.2f}) mm, attached "
              f"to ({1e3 * q[0]:.2f}, {1e3 * q[1]:.2f}, {1e3 * q[2]:.2f}) mm, "
              f"{1e3 * norm(sub(q, p)):.2f} mm away")
    return {"times": times, "tracks": tracks, "t0": t0, "to_model": to_model, "rest": rest,
            "attached": attached, "settled_drop": dm}


def write_case(capture, outdir, suffix, rest_points, markers_name, duration):
    """Step 5: the tracks of one capture, each marker translated so that it starts at
    rest_points[marker]; writes markers_name too when given."""
    times, tracks, t0, to_model = capture["times"], capture["tracks"], capture["t0"], capture["to_model"]
    offset = {m: sub(rest_points[m], to_model(capture["rest"][m])) for m in TIP}
    os.makedirs(outdir, exist_ok=True)
    if markers_name:
        with open(os.path.join(outdir, markers_name), "w") as f:
            f.write("name,x,y,z\n")
            for m in TIP:
                q = add(to_model(capture["rest"][m]), offset[m])
                f.write(f"{m},{q[0]:.6f},{q[1]:.6f},{q[2]:.6f}\n")
    frames = [k for k in range(len(times)) if t0 < times[k] <= t0 + duration + 1e-9]
    if times[-1] < t0 + duration:
        print(f"the capture ends {times[-1] - t0:.3f} s after the release, before {duration} s")
    fmt = lambda v: f"{v:.6f}"  # noqa: E731
    occluded = 0
    observed = f"observed{suffix}.csv"
    with open(os.path.join(outdir, observed), "w") as f:
        f.write("t," + ",".join(f"{m}_{c}" for m in TIP for c in "xyz") + "\n")
        first_row = [add(to_model(capture["rest"][m]), offset[m]) for m in TIP]
        f.write("0," + ",".join(fmt(v) for q in first_row for v in q) + "\n")
        for k in frames:
            cells = []
            for m in TIP:
                p = tracks[m][k]
                if p is None:
                    cells += ["", "", ""]
                    occluded += 1
                else:
                    cells += [fmt(v) for v in add(to_model(p), offset[m])]
            f.write(f"{times[k] - t0:.4f}," + ",".join(cells) + "\n")
    print(f"wrote {outdir}/{(markers_name + ' and ') if markers_name else ''}{observed}: "
          f"1 + {len(frames)} frames, t = 0 … {times[frames[-1]] - t0:.4f} s, "
          f"{occluded} occluded marker samples")


# --- comparing a simulation with the observed tracks -------------------------------------
def hermite(times, points, t):
    """Cubic Hermite interpolation through (times, points) at t, slopes by centred
    differences (one-sided at the ends); None outside the samples."""
    if not times[0] <= t <= times[-1]:
        return None
    i = max(0, min(len(times) - 2, next(k for k in range(1, len(times)) if times[k] >= t) - 1))

    def slope(j):
        a, b = max(0, j - 1), min(len(times) - 1, j + 1)
        return scale(sub(points[b], points[a]), 1.0 / (times[b] - times[a]))

    h = times[i + 1] - times[i]
    s = (t - times[i]) / h
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    return add(add(scale(points[i], h00), scale(slope(i), h10 * h)),
               add(scale(points[i + 1], h01), scale(slope(i + 1), h11 * h)))


def centroid_drop(times, tracks):
    """The Tip centroid's height relative to the first frame, (t, z − z₀) per frame."""
    z0 = tip_centroid(tracks, 0)[2]
    return [(times[k], tip_centroid(tracks, k)[2] - z0) for k in range(len(times))
            if tip_centroid(tracks, k) is not None]


def ringing_period(samples):
    """Mean period of the ringing and the minima it is taken from: successive minima of
    z(t), each refined by a parabola through its frame and the two neighbours; a minimum
    within 50 ms of the previous one is noise at a flat trough and skipped (as
    tests/test_real_beam.cpp does)."""
    t, z = [s[0] for s in samples], [s[1] for s in samples]
    minima = []
    for k in range(1, len(z) - 1):
        if not (z[k] < z[k - 1] and z[k] <= z[k + 1]):
            continue
        curvature = z[k - 1] - 2 * z[k] + z[k + 1]
        shift = 0.5 * (z[k - 1] - z[k + 1]) / curvature if curvature > 0 else 0.0
        at = t[k] + shift * 0.5 * (t[k + 1] - t[k - 1])
        if not minima or at - minima[-1] > 0.05:
            minima.append(at)
    period = (minima[-1] - minima[0]) / (len(minima) - 1) if len(minima) > 2 else float("nan")
    return period, minima


def compare(capture, observed_path, simulated_path):
    """Prints the simulation's distance from the observed tracks, its settled sag and its
    ringing period next to the capture's; returns the RMS in mm."""
    obs_t, obs = read_capture(observed_path, TIP)
    sim_t, sim = read_capture(simulated_path, TIP)
    residuals = {m: [] for m in TIP}
    for k, t in enumerate(obs_t):
        for m in TIP:
            x = hermite(sim_t, sim[m], t)
            if obs[m][k] is not None and x is not None:
                residuals[m].append(sub(x, obs[m][k]))
    print(f"{simulated_path} against {observed_path}: "
          f"{len(residuals[TIP[0]])} frames, t = 0 … {obs_t[-1]:.3f} s")
    print("  marker     RMS |simulated − observed|, mean (x, y, z)")
    rms = print_residuals(residuals)
    print(f"  RMS {rms:.3f} mm")

    window = obs_t[-1] + 1e-9
    z_obs = centroid_drop(obs_t, obs)
    z_sim = [s for s in centroid_drop(sim_t, sim) if s[0] <= window]
    for label, z in (("observed ", z_obs), ("simulated", z_sim)):
        trough = min(z, key=lambda s: s[1])
        period, minima = ringing_period(z)
        print(f"  {label}: first trough {-1e3 * trough[1]:6.2f} mm at {1e3 * trough[0]:5.0f} ms; "
              f"ringing period {1e3 * period:6.1f} ms ({len(minima)} minima, "
              f"{', '.join(f'{1e3 * m:.0f}' for m in minima)} ms)")
    print(f"  settled sag, observed (last second of the capture): "
          f"{-1e3 * capture['settled_drop'][2]:.2f} mm")
    if sim_t[-1] >= window + 1.0:
        tail = [s[1] for s in centroid_drop(sim_t, sim) if s[0] >= sim_t[-1] - 1.0]
        print(f"  settled sag, simulated (last second, t = {sim_t[-1] - 1:.1f} … {sim_t[-1]:.1f} s): "
              f"{-1e3 * sum(tail) / len(tail):.2f} mm")
    else:
        print(f"  (simulate past {window + 1:.1f} s, e.g. --end 5, for the simulated settled sag)")
    return rms


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("data", nargs="?", default="/work/shared/data/real/silicone-beam",
                    help="directory of the captures (wide marker CSV)")
    ap.add_argument("--case", nargs="+", choices=list(CASES), default=list(CASES))
    ap.add_argument(
        "--outdir", default=os.path.join(os.path.dirname(here), "yaml/examples/silicone-beam")
    )
    ap.add_argument("--duration", type=float, default=1.5, help="seconds after the release")
    ap.add_argument("--compare", metavar="SIMULATED.csv",
                    help="compare kelvin's simulated markers.csv with the case's observed tracks")
    args = ap.parse_args()
    if not os.path.isdir(args.data):
        sys.exit(f"{args.data}: not a directory (give the directory that holds the captures)")

    if args.compare:
        if len(args.case) != 1:
            sys.exit("--compare needs one --case")
        name = args.case[0]
        with contextlib.redirect_stdout(io.StringIO()):  # the registration, quietly
            capture = prepare(os.path.join(args.data, CASES[name][0]))
        compare(capture, os.path.join(args.outdir, f"observed{CASES[name][1]}.csv"), args.compare)
        return

    for name in args.case:
        capture_file, suffix = CASES[name]
        print(f"=== {name}")
        capture = prepare(os.path.join(args.data, capture_file))
        if name == "gravity":
            write_case(capture, args.outdir, suffix, capture["attached"], "markers.csv", args.duration)
            continue
        # A load case: the same balls, registered from its own capture. Share the gravity
        # case's rest points when its own come out within SHARED_REST of them.
        shared_path = os.path.join(args.outdir, "markers.csv")
        if not os.path.exists(shared_path):
            sys.exit(f"{shared_path} missing: run the gravity case first")
        shared = read_rest(shared_path)
        worst = 0.0
        for m in TIP:
            d = sub(capture["attached"][m], shared[m])
            worst = max(worst, norm(d))
            print(f"{m}: rest point {1e3 * norm(d):.2f} mm from markers.csv's "
                  f"({1e3 * d[0]:+.2f}, {1e3 * d[1]:+.2f}, {1e3 * d[2]:+.2f})")
        if worst <= SHARED_REST:
            print(f"within {1e3 * SHARED_REST} mm: tracks translated onto markers.csv")
            write_case(capture, args.outdir, suffix, shared, None, args.duration)
        else:
            print(f"{1e3 * worst:.2f} mm > {1e3 * SHARED_REST} mm: own rest file markers{suffix}.csv")
            write_case(capture, args.outdir, suffix, capture["attached"], f"markers{suffix}.csv",
                       args.duration)


if __name__ == "__main__":
    main()
