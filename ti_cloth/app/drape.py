"""The Cusick drape test (BS 5058 / ISO 9073-9) on a scan, and a Fabric fitted to it (issue 57).

A disc of fabric (DISC across) clamped between two discs (SUPPORT across) falls into folds.
Its measures, from any triangulated surface of it (a scan in metres, any orientation, or a
simulated drape):

- orientation (orient): the drape's axis is first the direction of least spread of its points
  (a drape is wider than it is tall), then the normal of the clamped region (the points within
  the support's radius, flat between the clamping discs) through its centre, pointing up from
  the hem to the clamped top (those points lie above the rest);
- drape coefficient DC = (A_shadow - A_support) / (A_specimen - A_support), the shadow cast
  along the axis rasterised at PIXEL (1 for a fabric that stays flat);
- the silhouette: the shadow's radius r(phi) in BINS angles about the axis; its folds, the
  maxima standing FOLD_DEPTH above the troughs on both sides; its anisotropy
  2 |c2| / mean(r), c2 = mean(r e^(-2 i phi)), and the angle of its longer axis, -arg(c2) / 2
  (r = R + b cos 2 (phi - a) has c2 = b e^(-2 i a) / 2):
  a fabric stiffer along the warp than the weft reaches further along the warp.

A top-view silhouette image (read_silhouette: the shadow darker than its background, its
pixel side given) has the coefficient, folds and silhouette, about the shadow's centroid, and
no drop: its fit matches the coefficient and the silhouette's anisotropy instead.

The fit (fit_cusick): the Fabric of a given weight whose simulated drape has the scan's drop
and drop anisotropy (a silhouette's coefficient and anisotropy), its bending (warp, weft) =
G (e^s, e^-s) with s >= 0 (a scan has no grain mark: the warp is taken along the scan's stiffer
direction), by Gauss-Newton on (log G, s), its Jacobian by forward differences at the start and
Broyden's secant updates after each step: a settle per iteration (simulate: the disc of `rings`
rings clamped within the support's radius, settled by implicit Euler under drag until no point
moves faster than SETTLED), three at the start. A drape can snap from one fold pattern to
another late (a 12-ring disc at 2 s, its anisotropy moving 2 % and its folds from 2 to 4), so a
settle runs until it is still, not for a fixed time: a drape measured while moving would be
fitted to a shape no scan of a settled specimen has. Derivative-free in the solver's sense:
the fold pattern of a drape is a bifurcation of its equilibrium, whose gradient through the
implicit solver's Hessian says nothing about which folds appear; the measures fitted, the
mean drop of the surface outside the support and its second harmonic (the fabric drops less
along its stiffer direction), are area-weighted means of the points, continuous in them, and
change smoothly with the parameters between bifurcations (a silhouette's coefficient moves in
raster steps of 0.5 mm cells; its fit still recovers a synthetic drape's bending, measured
0.1 %). The uncertainty reported is the change of the parameters that moves the measures by
the fit's residual or by 1e-3, whichever is larger, through the Jacobian at the best point
found.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..inputs.validation import finite_number, require

DISC = 0.30            # the specimen's diameter [m] (BS 5058: 24, 30 or 36 cm)
SUPPORT = 0.18         # the clamping discs' diameter [m]
PIXEL = 5e-4           # the shadow's raster [m]
BINS = 360             # silhouette angles
FOLD_DEPTH = 3e-3      # a fold stands this far above its troughs [m]
AREA_TOLERANCE = 0.2   # a scan's surface area within this of the disc's, relative
CONVERGED = 2e-3       # the fit stops once a step changes log G and s by less than this
STEP = 0.15            # the finite differences' step in log G and s
ITERATIONS = 8         # Gauss-Newton steps at most
START_SPLIT = 0.3      # s at the start: the drop's harmonic is flat in s at 0 (even in s)
SETTLED = 1e-4         # a drape has settled once no point moves faster than this [m/s]
SETTLE_CHECK = 0.1     # its speed is read this often [s]
MOST_SECONDS = 8.0     # a settle stops after this long, still or not (warned of) [s]


def shadow_cover(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The centres (P, 2) [m] of the PIXEL raster cells the triangles (T, 3) of 2-D `points`
    (N, 2) cover, and the covered mask's cell count (its area / PIXEL^2)."""
    low = points.min(axis=0)
    shape = np.ceil((points.max(axis=0) - low) / PIXEL).astype(int) + 1
    covered = np.zeros(shape, bool)
    for a, b, c in points[triangles]:
        lo = np.floor((np.minimum(np.minimum(a, b), c) - low) / PIXEL).astype(int)
        hi = np.ceil((np.maximum(np.maximum(a, b), c) - low) / PIXEL).astype(int)
        gx, gy = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1),
                             indexing="ij")
        p = np.stack([gx, gy], -1) * PIXEL + low
        d = (b[1] - c[1]) * (a[0] - c[0]) + (c[0] - b[0]) * (a[1] - c[1])
        if d == 0:
            continue
        u = ((b[1] - c[1]) * (p[..., 0] - c[0]) + (c[0] - b[0]) * (p[..., 1] - c[1])) / d
        v = ((c[1] - a[1]) * (p[..., 0] - c[0]) + (a[0] - c[0]) * (p[..., 1] - c[1])) / d
        inside = (u >= 0) & (v >= 0) & (u + v <= 1)
        covered[gx[inside], gy[inside]] = True
    cells = np.argwhere(covered)
    return cells * PIXEL + low, len(cells)


def shadow_area(points: np.ndarray, triangles: np.ndarray) -> float:
    """The area [m^2] the triangles of 2-D `points` cover, on the PIXEL raster."""
    return shadow_cover(points, triangles)[1] * PIXEL ** 2


def circular_folds(radius: np.ndarray, depth: float = FOLD_DEPTH) -> int:
    """The maxima of a closed profile `radius` (around a circle, smoothed over three samples)
    that stand `depth` above the lowest point between them and each neighbouring maximum."""
    r = (np.roll(radius, 1) + radius + np.roll(radius, -1)) / 3
    peaks = np.flatnonzero((r >= np.roll(r, 1)) & (r > np.roll(r, -1)))
    if len(peaks) < 2:
        return len(peaks)
    count = 0
    for k, p in enumerate(peaks):
        before, after = peaks[k - 1], peaks[(k + 1) % len(peaks)]
        left = r[np.arange(before, before + (p - before) % len(r) + 1) % len(r)].min()
        right = r[np.arange(p, p + (after - p) % len(r) + 1) % len(r)].min()
        count += r[p] - max(left, right) >= depth
    return int(count)


def orient(vertices: np.ndarray, support: float = SUPPORT) -> tuple[np.ndarray, np.ndarray]:
    """(centre, up) of a drape (module doc): the clamped region's centroid and normal (found
    from the axis of least spread), pointing to the clamped top."""
    centre = vertices.mean(axis=0)
    _, _, rows = np.linalg.svd(vertices - centre, full_matrices=False)
    up = rows[2]
    for _ in range(3):            # the clamped region's centre and normal (it is flat)
        offset = vertices - centre
        along = offset @ up
        across = np.linalg.norm(offset - np.outer(along, up), axis=1)
        inner = across < 0.45 * support
        if inner.sum() >= 3:
            centre = vertices[inner].mean(axis=0)
            _, _, rows = np.linalg.svd(vertices[inner] - centre, full_matrices=False)
            up = rows[2] if rows[2] @ up >= 0 else -rows[2]
    offset = vertices - centre
    along = offset @ up
    across = np.linalg.norm(offset - np.outer(along, up), axis=1)
    inner = across < 0.5 * support
    if inner.any() and (~inner).any() and along[inner].mean() < along[~inner].mean():
        up = -up
    return centre, up


@dataclass(frozen=True)
class Drape:
    """A drape's measures (module doc): coefficient, folds, silhouette radii [m] (BINS,),
    anisotropy, long_axis [rad] in the frame (first, second) about the axis; drop [m], the
    mean depth of the surface outside the support below the support's plane (area-weighted,
    continuous in the points: what the fit matches), drop_anisotropy 2 |d2| / drop,
    d2 = the area-weighted mean of depth e^(-2 i phi), and stiff_axis = -arg(-d2) / 2, the
    direction in which the fabric drops least."""

    coefficient: float
    folds: int
    radii: np.ndarray
    anisotropy: float
    long_axis: float
    drop: float
    drop_anisotropy: float
    stiff_axis: float


def measure(vertices: np.ndarray, triangles: np.ndarray, disc: float = DISC,
            support: float = SUPPORT, frame=None) -> Drape:
    """The measures of a drape's surface (vertices [m], triangles); `frame` = (centre, up,
    first): its axis and the direction angles are taken from (default: orient, and the
    direction of the axis' smallest component's axis for `first`)."""
    if frame is None:
        centre, up = orient(vertices, support)
        first = np.eye(3)[np.argmin(np.abs(up))]
    else:
        centre, up, first = (np.asarray(v, np.float64) for v in frame)
    first = first - (first @ up) * up
    first /= np.linalg.norm(first)
    second = np.cross(up, first)
    offset = vertices - centre
    flat = np.stack([offset @ first, offset @ second], 1)
    cells, _ = shadow_cover(flat, triangles)
    coefficient, folds, radii, anisotropy, long_axis = silhouette(cells, PIXEL, disc, support)
    height = offset @ up
    across = np.hypot(flat[:, 0], flat[:, 1])
    top = height[across < 0.5 * support].mean() if (across < 0.5 * support).any() else height.max()
    corners = flat[triangles].mean(axis=1)
    depth = top - height[triangles].mean(axis=1)
    x = vertices[triangles]
    area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)
    outside = area * (np.hypot(corners[:, 0], corners[:, 1]) > 0.5 * support)
    drop = float((outside * depth).sum() / outside.sum())
    d2 = (outside * depth * np.exp(-2j * np.arctan2(corners[:, 1], corners[:, 0]))).sum() / outside.sum()
    return Drape(coefficient, folds, radii, anisotropy, long_axis, drop,
                 float(2 * abs(d2) / drop), float(-np.angle(-d2) / 2))


def silhouette(cells: np.ndarray, pixel: float, disc: float = DISC, support: float = SUPPORT):
    """(coefficient, folds, radii, anisotropy, long_axis) of a shadow given as the centres
    (P, 2) [m] of its covered cells of side `pixel` about the drape's axis (module doc)."""
    outer, inner = np.pi * (disc / 2) ** 2, np.pi * (support / 2) ** 2
    coefficient = (len(cells) * pixel ** 2 - inner) / (outer - inner)
    angle = np.arctan2(cells[:, 1], cells[:, 0])
    which = np.minimum(((angle + np.pi) / (2 * np.pi) * BINS).astype(int), BINS - 1)
    radii = np.zeros(BINS)
    np.maximum.at(radii, which, np.hypot(cells[:, 0], cells[:, 1]))
    phi = (np.arange(BINS) + 0.5) / BINS * 2 * np.pi - np.pi
    c2 = np.mean(radii * np.exp(-2j * phi))
    return (float(coefficient), circular_folds(radii), radii, float(2 * abs(c2) / radii.mean()),
            float(-np.angle(c2) / 2))


def read_silhouette(path, pixel: float, disc: float = DISC, support: float = SUPPORT) -> Drape:
    """The measures of a top-view silhouette image (PNG, JPEG, ...: the shadow darker than its
    background, `pixel` [m] a side), about the shadow's centroid; it has no drop (None)."""
    import imageio.v3 as iio

    pixel = finite_number("pixel", pixel, 0.0, strict=True, unit="m")
    try:
        image = np.asarray(iio.imread(path), np.float64)
    except (OSError, ValueError) as err:
        raise ValueError(f"{path}: not an image imageio can read ({err})") from None
    grey = image[..., :3].mean(axis=-1) if image.ndim == 3 else image
    low, high = grey.min(), grey.max()
    require(high > low, f"{path}: pixels", f"all {low}", "a dark shadow on a lighter background")
    rows, cols = np.nonzero(grey < 0.5 * (low + high))
    cells = np.stack([cols, -rows], 1) * pixel         # x right, y up
    cells = cells - cells.mean(axis=0)
    coefficient, folds, radii, anisotropy, long_axis = silhouette(cells, pixel, disc, support)
    require(0.0 < coefficient <= 1.05, "pixel", pixel,
            f"the side of the image's pixels in metres: its shadow of {len(cells)} pixels "
            f"gives a drape coefficient of {coefficient:.3g} for a {disc} m disc on a "
            f"{support} m support, not one in (0, 1]")
    return Drape(coefficient, folds, radii, anisotropy, long_axis, None, None, long_axis)


def read_scan(path, disc: float = DISC, support: float = SUPPORT):
    """(vertices, triangles) of a Cusick scan (an OBJ, PLY, ... in metres, any triangulation
    and orientation: tc.load_mesh), checked: triangles there, finite coordinates (load_mesh),
    the surface area that of a disc of diameter `disc` within AREA_TOLERANCE, and wider than
    the support."""
    from ..body.mesh import load_mesh

    disc = finite_number("disc", disc, 0.0, strict=True, unit="m")
    support = finite_number("support", support, 0.0, strict=True, unit="m")
    require(support < disc, "support", support, f"less than the disc's diameter {disc} m")
    mesh = load_mesh(path)
    require(mesh.triangle_count > 0, f"{path}: triangles", 0, "at least one (a surface scan)")
    x, t = mesh.vertices, mesh.triangles
    area = 0.5 * np.linalg.norm(np.cross(x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]]),
                                axis=1).sum()
    expected = np.pi * (disc / 2) ** 2
    require(abs(area / expected - 1) <= AREA_TOLERANCE, "disc", disc,
            f"the diameter of the scanned specimen: {path} has the area "
            f"{area:.4g} m^2 of a {2 * math.sqrt(area / np.pi):.3g} m disc, not the "
            f"{expected:.4g} m^2 of a {disc} m one (is the scan in metres?)")
    return x, t


def cusick_simulation(fabric, disc: float = DISC, support: float = SUPPORT, rings: int = 12,
                      dt: float = 1 / 200, drag: float = 5.0):
    """(the Simulation, the disc's Mesh) of `fabric`'s disc on the support, at rest and flat:
    a disc_mesh of `rings` rings, its particles within the support's radius pinned, its warp
    along x, stepped by implicit Euler under `drag` (simulate settles it)."""
    from ..body.mesh import disc_mesh
    from ..body.topology import Cloth
    from ..simulation import Simulation

    mesh = disc_mesh(disc / 2, rings)
    radius = np.hypot(mesh.vertices[:, 0], mesh.vertices[:, 2])
    cloth = Cloth(mesh, fabric, pinned=np.flatnonzero(radius <= support / 2 + 1e-9),
                  warp=(1.0, 0.0, 0.0))
    return Simulation(cloth, integrator="implicit_euler", dt=dt, drag=drag), mesh


def simulate(fabric, disc: float = DISC, support: float = SUPPORT, rings: int = 12,
             seconds: float = MOST_SECONDS, dt: float = 1 / 200, drag: float = 5.0):
    """(positions, triangles) of `fabric`'s disc draped on the support: a disc_mesh of
    `rings` rings clamped within the support's radius, settled by implicit Euler under `drag`
    until no point moves faster than SETTLED (read every SETTLE_CHECK), for `seconds` at most:
    a drape still moving then is warned of (RuntimeWarning), its measures a moving drape's.
    Its steps' CG solves stop at their cap of 200 iterations (96 % of them on a 12-ring disc,
    a damped step each) unwarned: the settle is judged by its speed, and a cap of 1,000
    (every solve converged) reached the same drape within 3e-6 m at 2 s, and the same fit at
    16 rings (bending to 1e-8), in 2.1x the time."""
    from ..integrators.base import unconverged_unreported

    seconds = finite_number("seconds", seconds, 0.0, strict=True, unit="s")
    sim, mesh = cusick_simulation(fabric, disc, support, rings, dt, drag)
    most, check, taken = max(1, round(seconds / dt)), max(1, round(SETTLE_CHECK / dt)), 0
    while taken < most:
        steps = min(check, most - taken)
        with unconverged_unreported():
            sim.step(steps)
        taken += steps
        speed = float(np.linalg.norm(sim.velocities(), axis=1).max())
        if speed < SETTLED:
            return sim.positions(), mesh.triangles
    warnings.warn(f"the Cusick drape had not settled after seconds={seconds:g} s: a point still "
                  f"moves at {speed:.2g} m/s (settled: under {SETTLED:g} m/s), so its measures "
                  "are a moving drape's; give it more seconds (ti-cloth fit --seconds)",
                  RuntimeWarning, stacklevel=2)
    return sim.positions(), mesh.triangles


SIMULATED_FRAME = ((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0))   # centre, up, warp


@dataclass(frozen=True)
class DrapeFit:
    """fit_cusick's answer: the Fabric, the scan's and the fit's measures, the residual of the
    measures fitted (log drop and drop anisotropy; a silhouette's coefficient and anisotropy),
    the parameters' uncertainty (relative, of G_warp and G_weft), the warp's angle in the
    scan's frame [rad] and the drapes simulated."""

    fabric: object
    scan: Drape
    fitted: Drape
    residual: tuple
    uncertainty: tuple
    warp_angle: float
    evaluations: int


def fit_cusick(scan: Drape, weight: float, disc: float = DISC, support: float = SUPPORT,
               stretch: float = 1e3, shear: float = 50.0, rings: int = 12,
               seconds: float = MOST_SECONDS, iterations: int = ITERATIONS,
               progress=None) -> DrapeFit:
    """The Fabric of `weight` [g/m^2] whose simulated drape has the scan's drop and drop
    anisotropy (a silhouette's: its coefficient and anisotropy; module doc), each drape settled
    for `seconds` at most (simulate); `progress(step)` is called after each simulated drape."""
    from ..body.fabric import Fabric

    density = finite_number("weight", weight, 0.0, strict=True, unit="g/m^2") / 1000.0
    evaluations = [0]

    def drape(u):
        g, s = math.exp(u[0]), max(u[1], 0.0)
        fabric = Fabric(density=density, stretch=stretch, shear=shear,
                        bending=(g * math.exp(s), g * math.exp(-s)), damping=1e-3)
        x, t = simulate(fabric, disc, support, rings, seconds)
        evaluations[0] += 1
        if progress is not None:
            progress(evaluations[0])
        measured = measure(x, t, disc, support, SIMULATED_FRAME)
        return fabric, measured, features(measured)

    def features(d: Drape) -> np.ndarray:
        if shadow_only:
            return np.array([d.coefficient, d.anisotropy])
        return np.array([math.log(d.drop), d.drop_anisotropy])

    shadow_only = scan.drop is None
    target = features(scan)
    # G from the bending length whose cantilever droops past the support's edge as the disc
    # does: c^3 = G / W with the overhang (disc - support) / 2 standing at c ~ overhang / 2
    overhang = (disc - support) / 2
    u = np.array([math.log(density * 9.81 * (overhang / 2) ** 3), START_SPLIT])
    fabric, measured, f = drape(u)
    columns = []
    for k in range(2):                      # the Jacobian by forward differences, once
        probe = u.copy()
        probe[k] += STEP
        columns.append((drape(probe)[2] - f) / STEP)
    jacobian = np.stack(columns, 1)
    best = (fabric, measured, f, u)
    for _ in range(iterations):
        change = np.linalg.lstsq(jacobian, target - f, rcond=None)[0]
        change = np.clip(change, -1.0, 1.0)
        new_u = u + change
        new_u[1] = max(new_u[1], 0.0)
        fabric, measured, new_f = drape(new_u)
        moved = new_u - u                   # Broyden's update: the secant along the step
        if moved @ moved > 0:
            jacobian = jacobian + np.outer(new_f - f - jacobian @ moved, moved) / (moved @ moved)
        u, f = new_u, new_f
        if np.linalg.norm(target - f) < np.linalg.norm(target - best[2]):
            best = (fabric, measured, f, u)
        if np.all(np.abs(moved) < CONVERGED):
            break
    fabric, measured, f, u = best
    residual = target - f
    floor = np.array([1e-3, 1e-3])           # a scan's noise: 0.1 % of the drop
    spread = np.linalg.pinv(jacobian) @ np.maximum(np.abs(residual), floor)
    du = np.abs(spread)
    uncertainty = (float(math.expm1(du[0] + du[1])), float(math.expm1(du[0] + du[1])))
    return DrapeFit(fabric, scan, measured, tuple(float(r) for r in residual), uncertainty,
                    scan.stiff_axis, evaluations[0])
