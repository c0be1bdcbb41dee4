"""Garments (body/panels.py, physics/sewing.py): pattern panels triangulated and checked
against their outline's own area and edges, wrapped with the lengths a cylinder keeps, seams
paired along their edges, and sewing that closes each seam no faster than its speed,
conserves momentum, stays shut and resumes with the same bits."""

from pathlib import Path

import numpy as np
import pytest
from helpers import report

import ti_cloth as tc
from ti_cloth.app.scene import load_scene
from ti_cloth.inputs.scene_file import SceneError

ROUNDING = 1e-12
TRAPEZOID = [(-0.3, 0.0), (0.3, 0.0), (0.2, 0.5), (-0.2, 0.5)]
NOTCHED = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.6, 1.0), (0.5, 0.4), (0.4, 1.0), (0.0, 1.0)]


def shoelace(outline):
    x, y = np.asarray(outline, float).T
    return 0.5 * abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def signed_areas(points, triangles):
    a, b, c = (points[triangles[:, k]] for k in range(3))
    return 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])


@pytest.mark.parametrize("outline, h", [(TRAPEZOID, 0.02), (NOTCHED, 0.05),
                                        (TRAPEZOID[::-1], 0.1)])
def test_a_panel_fills_its_outline_with_near_equilateral_triangles(outline, h):
    """The triangles cover exactly the outline's area (every one counter-clockwise, none
    overlapping: their signed areas sum to the polygon's), the outline's points lie on its
    edges no more than h apart, and the triangles are near equilateral, about h on a side
    (quality 4 sqrt(3) A / sum of squared sides: 1 for equilateral)."""
    piece = tc.panel(outline, h)
    points, triangles = piece.flat, piece.mesh.triangles
    areas = signed_areas(points, triangles)
    assert (areas > 0).all()
    assert abs(areas.sum() - shoelace(outline)) < ROUNDING
    corners = np.asarray(outline, float)
    for k, edge in enumerate(piece.edges):
        p, q = corners[k], corners[(k + 1) % len(corners)]
        along = points[edge]
        np.testing.assert_allclose(along[[0, -1]], [p, q], atol=ROUNDING)
        cross = (q - p)[0] * (along - p)[:, 1] - (q - p)[1] * (along - p)[:, 0]
        assert np.abs(cross).max() < ROUNDING
        assert np.linalg.norm(np.diff(along, axis=0), axis=1).max() <= h * (1 + 1e-9)
    sides = np.stack([np.linalg.norm(points[triangles[:, i]] - points[triangles[:, j]], axis=1)
                      for i, j in ((0, 1), (1, 2), (2, 0))], axis=1)
    quality = 4 * np.sqrt(3) * areas / (sides ** 2).sum(axis=1)
    report("panel quality min, mean; mean side / h", (quality.min(), quality.mean(),
                                                      sides.mean() / h), "> 0.5, > 0.9, ~1")
    assert quality.min() > 0.5 and quality.mean() > 0.9 and 0.85 < sides.mean() / h < 1.15
    again = tc.panel(outline, h)
    np.testing.assert_array_equal(again.flat, points)
    np.testing.assert_array_equal(again.mesh.triangles, triangles)


def test_wrapping_onto_a_cylinder_keeps_every_length_to_the_chords_sag():
    """Each triangle side of length L that turns through theta round a cylinder of radius R
    becomes a chord at most L theta^2 / 24 shorter (2 R sin(theta / 2) against R theta); the
    vertical lines keep their length; a cone's top stays on its circle."""
    piece = tc.panel(TRAPEZOID, 0.02)
    radius = 0.2
    wrapped = piece.wrapped(radius)
    flat, curved = piece.flat, wrapped.mesh.vertices
    np.testing.assert_allclose(np.hypot(curved[:, 0], curved[:, 2]), radius, atol=ROUNDING)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        a, b = piece.mesh.triangles[:, i], piece.mesh.triangles[:, j]
        length = np.linalg.norm(flat[a] - flat[b], axis=1)
        chord = np.linalg.norm(curved[a] - curved[b], axis=1)
        theta = np.abs(flat[a, 0] - flat[b, 0]) / radius
        assert (chord <= length + ROUNDING).all()
        assert (length - chord <= length * theta ** 2 / 24 + ROUNDING).all()
    cone = piece.wrapped(radius, flare=0.25).mesh.vertices
    top = np.isclose(flat[:, 1], 0.5)
    np.testing.assert_allclose(np.hypot(cone[top, 0], cone[top, 2]), radius, atol=ROUNDING)
    hem = np.isclose(flat[:, 1], 0.0)
    np.testing.assert_allclose(np.hypot(cone[hem, 0], cone[hem, 2]),
                               radius + 0.5 * np.sin(np.arctan(0.25)), atol=ROUNDING)
    with pytest.raises(ValueError, match="Panel.wrapped must be called once"):
        wrapped.wrapped(radius)


def test_seams_pair_each_point_with_the_one_at_its_place_along_the_other_edge():
    """Equal edges: one pair per point, a's start with b's end; edges of different lengths
    (so different counts): every point of both has a partner at about its place."""
    left = tc.panel([(0, 0), (0.3, 0), (0.3, 0.4), (0, 0.4)], 0.05)
    right = left.moved(translate=(0.35, 0.0, 0.0))
    garment = tc.Garment([left, right], [(0, 1, 1, 3)])
    a, b = garment.particles(0, 1), garment.particles(1, 3)
    pairs = garment.seam_pairs
    assert len(a) == len(b) == len(pairs)
    expected = np.sort(np.column_stack([a, b[::-1]]), axis=1)
    np.testing.assert_array_equal(pairs, expected[np.lexsort(expected.T[::-1])])
    mesh = garment.mesh
    np.testing.assert_allclose(mesh.vertices[pairs[:, 1], 1], mesh.vertices[pairs[:, 0], 1],
                               atol=ROUNDING)
    short = tc.panel([(0, 0), (0.3, 0), (0.3, 0.25), (0, 0.25)], 0.05).moved((0.35, 0, 0))
    uneven = tc.Garment([left, short], [(0, 1, 1, 3)])
    pairs = uneven.seam_pairs
    a, b = uneven.particles(0, 1), uneven.particles(1, 3)
    assert set(pairs.ravel()) == set(a) | set(b) and len(a) != len(b)
    places = uneven.mesh.uvs[:, 1]
    fraction = np.where(np.isin(pairs, a), places[pairs] / 0.4, places[pairs] / 0.25)
    assert np.abs(fraction[:, 0] - fraction[:, 1]).max() <= 0.5 * 0.05 / 0.25 + ROUNDING


def two_panels(gap=0.05, h=0.05):
    left = tc.panel([(0, 0), (0.3, 0), (0.3, 0.4), (0, 0.4)], h)
    garment = tc.Garment([left, left.moved(translate=(0.3 + gap, 0.0, 0.0))], [(0, 1, 1, 3)])
    return garment


def test_sewing_closes_a_seam_at_its_speed_conserving_momentum_and_keeps_it_shut(f64):
    """Two free panels 5 cm apart, no gravity: after the step ending at t every seam gap is
    at most max(0, 5 cm - speed t) (the sewing stage is the step's last), total momentum
    stays 0 (each pair's corrections are equal and opposite), and once shut the seam stays
    shut while the sheet falls from one pinned corner. Without sewing the gap stays."""
    garment = two_panels()
    pairs = garment.seam_pairs
    cloth = tc.Cloth(garment.mesh, tc.Material(), seams=pairs)
    speed = 0.4
    sim = tc.Simulation(cloth, integrator="xpbd", dt=1 / 600, gravity=(0.0, 0.0, 0.0),
                        sewing=tc.Sewing(speed=speed))
    mass = cloth.particle_mass[:, None]
    worst_excess, worst_momentum, gaps = 0.0, 0.0, []
    for _ in range(120):
        sim.step(1)
        x = sim.positions()
        gap = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
        gaps.append(gap.max())
        worst_excess = max(worst_excess, (gap - max(0.0, 0.05 - speed * sim.time)).max())
        worst_momentum = max(worst_momentum, np.abs((mass * sim.velocities()).sum(axis=0)).max())
    shut = next(k for k, g in enumerate(gaps) if g < ROUNDING) + 1
    report("gap above the sewn length (m), momentum (kg m/s), first gap, steps to shut",
           (worst_excess, worst_momentum, gaps[0], shut), f"<= 0, 0, {0.05 - speed / 600}, "
           f"<= {0.05 * 600 / speed}")
    assert worst_excess < ROUNDING and worst_momentum < ROUNDING
    # at rest, the first step moves nothing but the seams: each closes by speed x dt
    assert abs(gaps[0] - (0.05 - speed / 600)) < ROUNDING
    assert shut <= round(0.05 * 600 / speed) and max(gaps[shut - 1:]) < ROUNDING
    hanging = tc.Cloth(garment.mesh, tc.Material(), seams=pairs, pinned=[0])
    sim = tc.Simulation(hanging, integrator="xpbd", dt=1 / 600, sewing=tc.Sewing(speed=speed))
    unsewn = tc.Simulation(tc.Cloth(garment.mesh, tc.Material(), pinned=[0]),
                           integrator="xpbd", dt=1 / 600)
    sim.step(120)
    unsewn.step(120)
    widest = 0.0
    for _ in range(4):
        sim.step(60)
        x = sim.positions()
        widest = max(widest, np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1).max())
    x = unsewn.positions()
    report("seam gap while falling, sewn; unsewn after 0.2 s", (widest, np.linalg.norm(
        x[pairs[:, 0]] - x[pairs[:, 1]], axis=1).max()), "rounding; ~5 cm or more")
    assert widest < 1e-9
    assert np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1).max() > 0.04


def test_a_sewing_run_resumes_with_the_same_bits(f64, tmp_path):
    garment = two_panels()
    cloth = tc.Cloth(garment.mesh, tc.Material(), seams=garment.seam_pairs,
                     pinned=garment.particles(0, 2))
    make = lambda: tc.Simulation(cloth, integrator="xpbd", dt=1 / 600,  # noqa: E731
                                 sewing=tc.Sewing(speed=0.4))
    whole = make()
    whole.step(90)
    half = make()
    half.step(45)
    half.save_state(tmp_path / "half.npz")
    resumed = make()
    resumed.load_state(tmp_path / "half.npz")
    resumed.step(45)
    np.testing.assert_array_equal(resumed.positions(), whole.positions())
    np.testing.assert_array_equal(resumed.velocities(), whole.velocities())
    other = tc.Simulation(cloth, integrator="xpbd", dt=1 / 600, sewing=tc.Sewing(speed=0.5))
    with pytest.raises(tc.StateMismatch):
        other.load_state(tmp_path / "half.npz")


def test_bad_panels_seams_and_sewing_are_refused_by_name():
    piece = tc.panel(TRAPEZOID, 0.1)
    cloth = tc.Cloth(piece.mesh, tc.Material())
    cases = [
        (lambda: tc.panel([(0, 0), (1, 0)], 0.1), "outline must be at least 3 points"),
        (lambda: tc.panel([(0, 0), (1, 1), (1, 0), (0, 1)], 0.1),
         "outline must be a polygon that does not cross itself (edges (0, 2) cross)"),
        (lambda: tc.panel([(0, 0), (0, 0), (1, 0), (0, 1)], 0.1), "outline[[0]] must be a point"),
        (lambda: tc.panel(TRAPEZOID, 0.0), "edge_length must be a finite number > 0.0 m"),
        (lambda: tc.panel(TRAPEZOID, 1e-5), "edge_length must be at least"),
        (lambda: tc.panel([(0, 0), (100, 100), (100, 100.01)], 0.005),
         "edge_length must be at least 0.0539 m for an outline this size"),
        (lambda: tc.panel(TRAPEZOID, 0.1).wrapped(0.05),
         "Panel.wrapped radius must be at least 0.0955 m for this panel"),
        (lambda: tc.panel([(0.347, 0.47), (0.169, -0.347), (0.551, -0.636), (0.723, -0.599),
                           (0.398, -0.11), (0.622, -0.108), (0.55, -0.065)], 0.28),
         "outline edge 4 must be kept by the triangulation"),
        (lambda: tc.Garment([piece], [(0, 1, 1, 3)]), "seams[0] panel must be a panel index"),
        (lambda: tc.Garment([piece, piece], [(0, 1, 1, 9)]), "seams[0] edge of panel 1"),
        (lambda: tc.Garment([piece, piece], [(0, 1, 1, 3), (1, 3, 0, 2)]),
         "seams[1] must be edges sewn once"),
        (lambda: tc.Cloth(piece.mesh, tc.Material(), seams=[(0, 0)]),
         "seams[[0]] must be two different particle indices"),
        (lambda: tc.Simulation(cloth, sewing=tc.Sewing()),
         "sewing must be None for a cloth without seams"),
        (lambda: tc.Sewing(speed=-1.0), "Sewing.speed must be"),
        (lambda: tc.panel(TRAPEZOID, 0.1).wrapped(0.2, gather=1.5),
         "Panel.wrapped gather must be"),
    ]
    for make, message in cases:
        with pytest.raises(ValueError) as caught:
            make()
        report("message", str(caught.value)[:160], message)
        assert message in str(caught.value)


def test_pleats_keep_every_length_of_the_line_they_gather():
    """panels.pleated: a line of the pattern laid in pleats (a / k) sin(k s) along a line
    `share` of its length keeps the length of every piece (a polyline through 4,001 points of
    it: within 1e-3, the chords' error at slopes up to 9), ends where the share puts it to
    within a pleat, and pleat_slope gives the slope whose pleats are 1 / share long."""
    from ti_cloth.body.panels import pleat_slope, pleated
    x = np.linspace(-0.35, 0.35, 4001)
    for share in (0.9, 0.48, 0.2):
        slope = float(pleat_slope(1 / share))
        wave = 2 * np.pi / 0.06
        s = pleated(x, share, slope, wave)
        curve = np.stack([s, slope / wave * np.sin(wave * s)], axis=1)
        pieces = np.linalg.norm(np.diff(curve, axis=0), axis=1)
        report(f"share {share}: piece length / pattern piece - 1", np.abs(pieces / np.diff(x) - 1).max(),
               "< 1e-3")
        assert np.abs(pieces / np.diff(x) - 1).max() < 1e-3
        assert abs(np.ptp(s) - share * 0.7) < 0.06


def test_a_gathered_panel_starts_pleated_at_its_top_and_rests_flat():
    """wrapped(gather=0.5): the top edge spans half its pattern length round the circle (to a
    pleat), lies in pleats whose depth the pattern's length sets (its points off the circle
    by up to (a / k)), the bottom edge is not gathered (on its circle, its full length), and
    the rest state is still the flat pattern (rest="uv": lengths the pattern's)."""
    from ti_cloth.body.panels import PLEAT_EDGES, pleat_slope
    rectangle = [(-0.3, 0.0), (0.3, 0.0), (0.3, 0.4), (-0.3, 0.4)]
    piece = tc.panel(rectangle, 0.02).wrapped(0.2, gather=0.5)
    x = piece.mesh.vertices
    top, bottom = piece.edges[2], piece.edges[0]
    radius = np.hypot(x[:, 0], x[:, 2])
    angle = np.arctan2(x[:, 0], x[:, 2])
    depth = pleat_slope(2.0) * PLEAT_EDGES * piece.edge_length / (2 * np.pi)
    report("top span / half the pattern's; deepest pleat / expected",
           (np.ptp(angle[top]) * 0.2 / 0.3, np.abs(radius[top] - 0.2).max() / depth), "1, 1")
    assert abs(np.ptp(angle[top]) * 0.2 - 0.3) < PLEAT_EDGES * piece.edge_length
    assert 0.8 < np.abs(radius[top] - 0.2).max() / depth <= 1.0 + 1e-9
    np.testing.assert_allclose(radius[bottom], 0.2, atol=1e-12)
    np.testing.assert_allclose(np.ptp(angle[bottom]) * 0.2, 0.6, rtol=1e-9)
    cloth = tc.Cloth(tc.Garment([piece], []).mesh, tc.Fabric(), warp="uv", rest="uv")
    np.testing.assert_allclose(cloth.face_area.sum(), 0.6 * 0.4, rtol=1e-9)


SKIRT = Path(__file__).parents[1] / "demos" / "skirt_walk.toml"


def test_scene_files_build_a_garment_and_refuse_bad_panels(tmp_path):
    scene = load_scene(SKIRT)
    assert len(scene.cloth.seam_indices) > 0 and scene.sewing == tc.Sewing(speed=0.3)
    assert scene.cloth.fabric and scene.cloth.particle_count == sum(
        p.mesh.vertex_count for p in scene.bodies[0].options["garment"].panels)
    text = SKIRT.read_text().replace('path = "assets/', f'path = "{SKIRT.parent}/assets/')
    for old, new, message in (
            ("seams = [[0, 1, 1, 3], [0, 3, 1, 1]]", "seams = [[0, 1, 2, 3]]",
             r"bodies\[0\]: seams\[0\] panel must be a panel index in \[0, 1\], got 2"),
            ("edge_length = 0.015\nwrap = 0.165\nflare = 0.35\nrotate",
             "edge_length = -1\nwrap = 0.165\nflare = 0.35\nrotate",
             r"bodies\[0\]\.panels\[1\]\.edge_length must be"),
            ("wrap = 0.165\nflare = 0.35\nrotate", "wrap = 0.165\nflare = 0.35\ngather = 0\nrotate",
             r"bodies\[0\]\.panels\[1\]\.gather must be a number in \[0\.05, 1\]"),
            ('particles = ["panel0_edge2", "panel1_edge2"]', 'particles = ["panel0_edge7"]',
             r"bodies\[0\]\.attachments\[0\]\.particles must be particle indices")):

        assert old in text
        path = tmp_path / "skirt.toml"
        path.write_text(text.replace(old, new))
        with pytest.raises(SceneError, match=message):
            load_scene(path)


def test_a_garment_refines_with_its_seams_and_waistband():
    """The skirt at resolutions 1, 2 and 4 (midpoint subdivision): each side seam of n pairs
    becomes one of f (n - 1) + 1, every pair joins points at the same height of the pattern
    (the two panels are the same shape), the points along the seams are all sewn, and the
    waistband holds the refined edges (f (n - 1) + 1 points each)."""
    scene = load_scene(SKIRT)
    coarse = len(scene.cloth.seam_indices)
    waist = len(scene.handles[0].particles)
    for factor in (1, 2, 4):
        refined = scene.refined(factor)
        cloth = refined.cloth
        pairs = cloth.seam_indices
        heights = cloth.mesh.uvs[:, 1]
        report(f"resolution {factor}: seam pairs, waistband", (len(pairs),
               len(refined.handles[0].particles)), (factor * (coarse - 2) + 2,
                                                    factor * (waist - 2) + 2))
        assert len(pairs) == factor * (coarse - 2) + 2        # two seams of n pairs each
        assert len(refined.handles[0].particles) == factor * (waist - 2) + 2   # two edges
        np.testing.assert_allclose(heights[pairs[:, 0]], heights[pairs[:, 1]], atol=1e-12)
        x, flat = cloth.particle_position, cloth.mesh.uvs
        side = np.isclose(np.abs(flat[:, 0]), 0.467 - (0.467 - 0.2592) * flat[:, 1] / 0.42)
        assert set(np.flatnonzero(side)) == set(pairs.ravel())
        assert (np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1) < 0.07).all()


def test_a_sewn_garment_exports_as_one_body(f64, tmp_path):
    """OBJ and PC2 of a garment hold every panel's triangles and points as one body."""
    import meshio

    from ti_cloth.export import read_pc2
    garment = two_panels()
    cloth = tc.Cloth(garment.mesh, tc.Material(), seams=garment.seam_pairs,
                     pinned=garment.particles(0, 2))
    sim = tc.Simulation(cloth, integrator="xpbd", dt=1 / 600)
    with tc.Exporter(tmp_path, ["obj", "pc2"], name="garment", cloth=cloth, fps=30) as export:
        for _ in range(3):
            sim.step(20)
            export.write(sim)
    read = meshio.read(tmp_path / "garment_body0_00002.obj")
    np.testing.assert_allclose(read.points, sim.positions(), atol=1e-12)
    np.testing.assert_array_equal(read.cells_dict["triangle"], garment.mesh.triangles)
    header, cached = read_pc2(tmp_path / "garment_body0.pc2")
    assert header["points"] == garment.mesh.vertex_count and header["samples"] == 3


@pytest.mark.parametrize("outline", [[(0.0, 0.0), (1.0, 0.0), (2.0, 0.0)],
                                     [(0.0, 0.0), (1.0, 0.0), (1.0, 1e-9), (0.0, 1e-9)]])
def test_an_outline_with_no_width_is_refused_naming_it(outline):
    """Collinear points, or a sliver thinner than half an edge length, are refused before
    triangulation (they were a Qhull precision error's traceback)."""
    with pytest.raises(ValueError, match="outline must be a polygon at least half an "
                                         "edge_length"):
        tc.panel(outline, edge_length=0.1)


def test_a_disc_too_big_for_the_machine_is_refused_before_it_is_built():
    with pytest.raises(ValueError, match=r"rings = 10000 makes 300,030,001 particles"):
        tc.disc_mesh(0.3, rings=10_000)
