"""Launch plans: one launch per phase of a step (runtime/plan.py's run, GPUs' plan), many
steps per launch on one worker and many steps per launch shared by a team of CPU workers
(stepping.py), with the two-phase spring force (evaluate once, gather with signs): every plan
gives the same bits (the same phases, exact IEEE arithmetic), with every stage a team launch
runs (strain limiting, colliders standing and scripted, tearing, wind, handles), and the
divergence guard must name the same step whichever plan ran."""

import importlib.util
import sys
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import taichi as ti

import ti_cloth as tc
from ti_cloth import stepping
from ti_cloth.contact.colliders.collision import ColliderSet
from ti_cloth.inputs import limits
from ti_cloth.integrators import Integrator
from ti_cloth.model import Model
from ti_cloth.physics.forces import ForceSettings, compute_forces
from ti_cloth.physics.handles import HandleSet
from ti_cloth.physics.strain_limit import StrainLimiter
from ti_cloth.runtime import backend, team
from ti_cloth.runtime import plan as runtime_plan
from ti_cloth.stages import STEP_ORDER, Stage, in_order

FUSED = ["explicit_euler", "symplectic_euler", "verlet"]


def sheet(n=6, damping="axial"):
    cloth = tc.Cloth(tc.grid_mesh(n, n), tc.Material(damping=damping), pinned=[n * (n - 1), n * n - 1])
    centre = cloth.particle_position.mean(axis=0)
    return cloth, centre + 1.3 * (cloth.particle_position - centre)   # start stretched: it moves


PLANS = ["launch per phase", "serial launch per step", "one worker", "pool of one", "team"]


def run(sim, plan, steps, monkeypatch, per_launch=100):
    """`steps` steps in the given plan; many-steps plans launch per_launch steps at a time."""
    if plan in ("launch per phase", "serial launch per step"):
        monkeypatch.setattr(runtime_plan, "SERIAL_SPRING_LIMIT",
                            -1 if plan == "launch per phase" else 10**9)
        for _ in range(steps):
            sim.step(1, plan="per stage")
        return
    many = sim.many_steps
    monkeypatch.setattr(many, "adaptive", False)
    # one worker: small launches (serial on the launching thread); pool of one and team: big
    # launches, the same kernel on one worker or two, whatever the cores, on the fixture's threads
    monkeypatch.setattr(many, "workers", 2 if plan == "team" else 1)
    monkeypatch.setattr(stepping, "TEAM_MIN_SPRING_STEPS", 0)
    # one worker: the serial variant (a small body's); pool of one and team: the pool's
    monkeypatch.setattr(stepping, "TEAM_MIN_SPRINGS", 1 << 62 if plan == "one worker" else 0)
    monkeypatch.setattr(stepping, "MAX_STEPS_PER_LAUNCH", per_launch)
    sim.step(steps, plan="many steps")


def fabric_sheet(curve=True, n=9, compression=1.0):
    """A denim sheet (membrane and bending elements, gathered per corner), started stretched:
    bent by the preset's BendingCurve (the mid-edge tangents), or without it by the isometric
    model. 81 particles: two of the implicit solves' blocks (conjugate_gradients.BLOCK), one
    for each worker of a team. With compression < 1 (Fabric.compression) it starts shortened
    instead, so that every triangle's warp and weft give way."""
    fabric = tc.Fabric.preset("denim", compression=compression)
    if not curve:
        fabric = tc.Fabric.preset("denim", bending_curve=None, compression=compression)
    cloth = tc.Cloth(tc.grid_mesh(n, n, (0.3, 0.3)), fabric, pinned=[n * (n - 1), n * n - 1])
    centre = cloth.particle_position.mean(axis=0)
    return cloth, centre + (1.1 if compression == 1.0 else 0.95) * (cloth.particle_position - centre)


def garment_sheet():
    """Two panels with a seam 5 cm open between them, sewn shut in the runs (sewing)."""
    piece = tc.panel([(0, 0), (0.5, 0), (0.5, 1.0), (0, 1.0)], 0.25)
    garment = tc.Garment([piece, piece.moved(translate=(0.55, 0.0, 0.0))], [(0, 1, 1, 3)])
    cloth = tc.Cloth(garment.mesh, tc.Material(), seams=garment.seam_pairs,
                     pinned=garment.particles(0, 2))
    return cloth, cloth.particle_position * 1.05


def braced_strands():
    """Two hair strands with ghosts and altitude springs, started bent: they swing."""
    body = tc.hair(2, 6, 0.3, mass=1e-3, bend=tc.SpringParams(20.0, 0.02))
    start = body.particle_position.copy()
    start[~body.pinned] += np.random.default_rng(4).normal(scale=3e-3, size=(int((~body.pinned).sum()), 3))
    return body, start


def contact_scene():
    """A plane 3 cm under the sheet and a sphere 1 cm under one of its particles, swept
    sideways along a path, with friction: the sheet thrown at them (THROW) reaches both
    within the runs."""
    return [tc.Plane(point=(0.0, 0.0, -0.03), normal=(0.0, 0.0, 1.0), thickness=0.005,
                     static_friction=0.4),
            tc.Sphere(centre=(0.37, 0.37, -0.26), radius=0.25, thickness=0.005,
                      static_friction=0.2, path=lambda t: (2.0 * t, 0.0, 0.0))]


THROW = (0.0, 0.0, -8.0)   # m/s, the sheet's start velocity


def animated_scene():
    """A growing icosphere under one corner (a callable motion), a plate rising under the
    sheet (samples at 1000 fps), with friction, and a still blade whose edge, between two
    columns of the sheet, only the sheet's edges meet (animated_edges.py): the thrown sheet
    meets all three."""
    blade = np.array([[0.5, -0.3, -0.015], [0.496, -0.3, -0.2], [0.504, -0.3, -0.2],
                      [0.5, 1.3, -0.015], [0.496, 1.3, -0.2], [0.504, 1.3, -0.2]])
    faces = np.array([[0, 1, 2], [3, 5, 4], [0, 3, 4], [0, 4, 1], [0, 2, 5], [0, 5, 3],
                      [1, 4, 5], [1, 5, 2]])
    ball = tc.sphere_mesh(0.25, (0.37, 0.37, -0.26), subdivisions=1)
    square = np.array([[-0.5, -0.5, -0.03], [1.5, -0.5, -0.03], [1.5, 1.5, -0.03],
                       [-0.5, 1.5, -0.03]])
    plate = tc.Mesh(square, np.array([[0, 1, 2], [0, 2, 3]]))
    rising = np.stack([square + [0.0, 0.0, 2.0 * k / 1000] for k in range(10)])
    return [tc.AnimatedMeshCollider(
                ball, lambda t: (0.37, 0.37, -0.26) + (ball.vertices - (0.37, 0.37, -0.26))
                * (1.0 + 4.0 * t), thickness=0.005, static_friction=0.2),
            tc.AnimatedMeshCollider(plate, rising, fps=1000, thickness=0.005,
                                    static_friction=0.4),
            tc.AnimatedMeshCollider(tc.Mesh(blade, faces), thickness=0.005)]


FEATURES = {"none": {}, "tearing": dict(tearing=0.2),
            "animated colliders": dict(colliders=animated_scene()),
            # two particles carried by a sphere moving along a path (not among the
            # colliders), let go part-way
            "attached": dict(handles=[tc.Attachment(
                [0, 1], tc.Sphere(radius=0.2, path=lambda t: (0.3 * t, 0.1 * np.sin(7 * t), 0.0)),
                release=0.0031)]),
            # strain limiting apart, the stages let a fused integrator's particles collide as
            # they move (stepping.TeamStages.collides_on_move)
            "all but strain limit": dict(
                tearing=0.4, colliders=contact_scene(),
                wind=tc.Wind(velocity=(1.0, 0.0, 2.0), turbulence=0.5, gust=0.3),
                handles=[tc.Handle([0, 1], lambda t: (0.3 * t, 0.1 * np.sin(7 * t), 0.0),
                                   release=0.0031)]),
            # every stage a tethered xpbd takes (tethers refuse tearing)
            "all but tearing": dict(
                strain_limit=tc.StrainLimit(max_strain=0.05), colliders=contact_scene(),
                wind=tc.Wind(velocity=(1.0, 0.0, 2.0)),
                handles=[tc.Handle([0, 1], lambda t: (0.3 * t, 0.0, 0.0), release=0.0031)]),
            "everything": dict(tearing=0.4, strain_limit=tc.StrainLimit(max_strain=0.05),
                               colliders=contact_scene(), wind=tc.Wind(velocity=(1.0, 0.0, 2.0)),
                               handles=[tc.Handle([0, 1], lambda t: (0.3 * t, 0.0, 0.0), release=0.0031)])}


@pytest.mark.parametrize("integrator, body, feature",
                         [(i, "sheet", f) for f in ("none", "tearing") for i in FUSED]
                         # moving colliders alone: within "all but strain limit" (fused, they
                         # collide as particles move) and "everything" (they do not)
                         + [("symplectic_euler", "sheet", f)
                            for f in ("all but strain limit", "everything")]
                         + [(i, "sheet", "everything") for i in ("xpbd", "pbd")]
                         # implicit Euler's CG with every stage compiled 7 s per plan: its own
                         # tearable paths, with the stages' shared code tested above
                         + [("implicit_euler", "sheet", "tearing")]
                         + [# an animated mesh is a stage of its own for every integrator (it
                            # is placed first): one integrator's plans test it
                            pytest.param("xpbd", "sheet", "animated colliders",
                                         marks=pytest.mark.slow),
                            ("xpbd", "garment", "attached"),
                            ("rk4", "sheet", "all but strain limit"),
                            ("symplectic_euler", "braced strands", "none"),
                            ("symplectic_euler", "fabric", "all but strain limit"),
                            ("rk4", "flat fabric", "none"),
                            # its chain of six stages, their alphas read at run time
                            ("stabilized_rk2", "flat fabric", "none"),
                            # softened compression in XPBD's constraints and in the
                            # implicit solves' Hessian
                            ("xpbd", "softened flat fabric", "none"),
                            # the curved fabric (BendingCurve) in the force and implicit
                            # paths; XPBD's triangles read it the same way, coloured, each
                            # swept in the passes it needs (XPBD.bending_tolerance)
                            ("implicit_euler", "fabric", "none"), ("xpbd", "fabric", "none"),
                            # implicit midpoint and TR-BDF2 share newton.py's phases
                            ("implicit_midpoint", "softened fabric", "none"),
                            ("tr_bdf2", "sheet", "everything"), ("tr_bdf2", "garment", "attached"),
                            ("xpbd", "braced strands", "none"),
                            # XPBD's BDF2 step: its history across steps and launches, with
                            # every stage moving particles it then restarts (xpbd.py)
                            ("xpbd bdf2", "sheet", "everything"),
                            # tethers (strain 0: they act on the stretched start) to the
                            # pins, a handle's let go, and across a seam (energies/tethers.py)
                            ("xpbd tethers", "sheet", "all but tearing"),
                            ("xpbd tethers", "garment", "attached")])
def test_every_launch_plan_takes_the_same_steps(threads, integrator, feature, body, monkeypatch):
    """The same bits in a launch per phase, in small launches on the launching thread and in
    big launches on one worker and on a team of two, for a sheet and for strands whose
    altitude springs are evaluated per element and gathered per corner (a team of two shares
    both), with each stage a team launch runs."""
    cloth, start = {"sheet": sheet, "braced strands": braced_strands,
                    "fabric": fabric_sheet, "flat fabric": lambda: fabric_sheet(curve=False),
                    "softened fabric": lambda: fabric_sheet(compression=0.05),
                    "softened flat fabric": lambda: fabric_sheet(curve=False, compression=0.05),
                    "garment": garment_sheet}[body]()
    runs = []
    kwargs = FEATURES[feature]
    position_based = integrator.split()[0] in ("pbd", "xpbd", "implicit_euler",
                                               "implicit_midpoint", "tr_bdf2")   # 1/480 s
    dt = (1 / 480 if position_based else 2e-5 if body == "sheet"
          else 0.5 * tc.stable_dt(cloth, integrator, 0.3))   # strands and fabric: its own
    steps = 2 * 100 + 7 if not position_based else 2 * 20 + 7
    made = {"xpbd bdf2": lambda: tc.XPBD(scheme="bdf2"),
            "xpbd tethers": lambda: tc.XPBD(scheme="bdf2", tethers=0.0)}
    sim = tc.Simulation(cloth, integrator=made[integrator]() if integrator in made
                        else integrator, dt=dt, drag=0.3, **kwargs)
    assert sim.many_steps is not None
    assert sim.many_steps.stages.collides_on_move == (
        "colliders" in kwargs and integrator in FUSED and "strain_limit" not in kwargs
        and feature != "animated colliders"    # an animated mesh is placed first
        and not len(cloth.seam_indices))       # and sewing moves particles in between
    for plan in PLANS:                                    # restart: the same start, kernels kept
        sim.restart()
        sim.set_positions(start)
        sim.set_velocities(np.tile(THROW, (cloth.particle_count, 1)))
        run(sim, plan, steps, monkeypatch, per_launch=100 if not position_based else 20)
        runs.append((sim.positions(), sim.velocities(), sim.torn_springs(), sim.step_count))
    x0, v0, torn0, n0 = runs[0]
    moved = np.abs(x0 - start).max()
    if "colliders" in kwargs:
        distance, _ = sim.collider_distance(x0)
        touching = int((distance < 0.0055).sum())
        assert touching > 0, "the sheet reached a collider"
    # Big launches on one worker and on a team run the same compiled kernel on chunk-aligned
    # slices (team.py): thread counts never change a bit.
    np.testing.assert_array_equal(runs[-2][0], runs[-1][0])
    np.testing.assert_array_equal(runs[-2][1], runs[-1][1])
    for plan, (x, v, torn, n) in zip(PLANS[1:], runs[1:]):
        print(f"{integrator}, {feature}, {plan}: moved {moved:.3g} m, torn {len(torn)} "
              f"springs, max |dx| against a launch per stage {np.abs(x - x0).max()}")
        assert moved > 1e-3 and n == n0 == steps and np.array_equal(torn, torn0)
        # A launch per phase, and a small launch on the launching thread, are other compiled
        # code running the same phases: with fast math (Taichi's default) LLVM contracted and
        # vectorised them differently, up to 2e-12 m apart over these steps; exact IEEE
        # arithmetic (runtime/backend.py) makes them the same operations in the same order.
        np.testing.assert_array_equal(x, x0)
        np.testing.assert_array_equal(v, v0)
    if feature == "tearing":
        assert len(torn0) > 0, "the 30 % stretch tears springs at a 20 % tear strain"


def test_a_team_shares_big_launches_and_one_worker_takes_small_ones(threads):
    cloth, _ = sheet()
    for integrator in ("symplectic_euler", tc.XPBD(iterations=5)):
        sim = tc.Simulation(cloth, integrator=integrator, dt=2e-5)
        many, model, work = sim.many_steps, sim.model, sim.integrator.step_work(sim.model)
        many.adaptive = False                # the size rule alone (a lent plan may have timings)
        small = stepping.TEAM_MIN_SPRING_STEPS // work
        assert many.workers == min(backend.cpu_threads(), backend.cpu_cores())
        assert many.workers_for(sim.integrator, model, small) == 1
        assert many.workers_for(sim.integrator, model, small + 1) == many.workers
        assert many.steps_per_launch(sim.integrator, model) == stepping.MAX_STEPS_PER_LAUNCH
    assert work == 7 * cloth.spring_count          # iterations + prediction and velocities
    big = SimpleNamespace(spring_count=stepping.SPRING_STEPS_PER_LAUNCH // 10, altitude_count=0,
                          face_count=0, hinge_count=0)
    assert many.steps_per_launch(tc.SymplecticEuler(), big) == 10
    moving = tc.Simulation(cloth, dt=1e-4, colliders=contact_scene()).many_steps
    assert moving.steps_per_launch(tc.SymplecticEuler(), model) == limits.SCHEDULED_STEPS


def team_slices(count: int, chunk: int, workers: int) -> list[tuple[int, int]]:
    """Each worker's slice [begin, end) of a loop of `count` items with `chunk` (team.py)."""
    @ti.kernel
    def slices(out: ti.types.ndarray()):
        for w in range(workers):
            begin, end = team.chunked_share(count, w, workers, chunk)
            out[w, 0], out[w, 1] = begin, end

    out = np.zeros((workers, 2), np.int32)
    slices(out)
    return [tuple(row) for row in out]


def loops_in(nodes) -> list:
    """Every Loop in `nodes` (runtime/plan.py), inside Repeats and Untils too."""
    found = []
    for node in nodes:
        if isinstance(node, (runtime_plan.Repeat, runtime_plan.Until)):
            found += loops_in(node.leaves)
        elif isinstance(node, runtime_plan.Phase):
            found += list(node.loops)
    return found


def test_a_team_shares_the_implicit_solves_blocks_among_all_its_workers(threads):
    """The implicit solves' loops over blocks of particles (conjugate_gradients.BLOCK, each
    block a serial loop: A p, CG's updates, the forces gathered, Newton's) are shared block
    by block, so a body of a few blocks gives every worker of a team some; sliced at
    team.CHUNK items, as loops over particles are, 16 blocks (32 x 32 particles) all went to
    one worker while the other waited at each barrier (CG iterations 1.4x slower)."""
    cloth, _ = fabric_sheet(n=12)                       # 144 particles: 3 blocks
    for integrator in (tc.ImplicitEuler(), tc.ImplicitMidpoint(), tc.TRBDF2()):
        sim = tc.Simulation(cloth, integrator=integrator, dt=1 / 240)
        work = sim.integrator.loaded_workspace(sim.model, sim.state)
        nodes = runtime_plan.nodes_of(sim.integrator, "phases", sim.model, sim.forces, work)
        over_blocks = [loop for loop in loops_in(nodes) if loop.count == work.block_count == 3]
        assert len(over_blocks) >= 4, integrator           # A p, two CG updates, the gather
        for loop in over_blocks:
            slices = team_slices(loop.count, loop.chunk, 2)
            assert slices[0][0] == 0 and slices[0][1] == slices[1][0] and slices[1][1] == 3
            assert all(end > begin for begin, end in slices), (loop.body.__name__, slices)
        # a loop over particles keeps its chunk-aligned slices (team.py's vectorised items)
        assert team_slices(cloth.particle_count, team.CHUNK, 2) == [(0, 64), (64, 144)]


def test_no_step_count_compiles_a_kernel_after_the_first_step(threads):
    """Whether launches run serially or as pool tasks is compiled into advance_many, and
    chosen by the body (stepping.TEAM_MIN_SPRINGS), not by the launch: a small body's
    launches are serial, a big body's pool tasks, and once the first step has built it no
    later count (step(6) after step(60), a launch of 4096 steps after one of 1) compiles
    another kernel. (Chosen per launch, by its work, step(6) after step(60) built the serial
    variant on the way.)"""
    for n, serial in ((8, True), (16, False)):
        cloth, _ = sheet(n)
        for integrator in ("symplectic_euler", tc.ImplicitEuler()):
            sim = tc.Simulation(cloth, integrator=integrator, dt=1e-4)
            assert sim.many_steps.serial(sim.model) == serial
            sim.step(60)
            built = backend.compilations(stepping.advance_many)   # distinct template sets so far
            for steps in (6, stepping.MAX_STEPS_PER_LAUNCH, 1, 60):
                sim.step(steps)
            assert backend.compilations(stepping.advance_many) == built, (n, integrator)


def test_big_launches_go_to_the_size_measured_faster_and_probe_the_other(threads):
    """Timed big launches (the first of each size ignored: it compiles) steer the choice to
    one worker when the team costs more than TEAM_MARGIN times as much per spring-step, and
    back; every PROBE_EVERY-th big launch tries the size not in favour. (Every size runs the
    same kernel: the choice never changes a bit.)"""
    cloth, _ = sheet()
    sim = tc.Simulation(cloth, dt=2e-5)
    model, integrator = sim.model, sim.integrator
    many = stepping.ManySteps(sim.many_steps.stages)   # no timings yet (a lent plan may have some)
    many.workers = 2
    big = stepping.TEAM_MIN_SPRING_STEPS // integrator.step_work(model) + 1
    work = big * integrator.step_work(model)
    picks = []
    for launch in range(3 * stepping.PROBE_EVERY):
        chosen = many.workers_for(integrator, model, big)
        picks.append(chosen)
        many.timed(chosen, work, (1.0 if chosen == 1 else 3.0) * work * 1e-9)
    # team (compiling), team (timed), one worker (compiling), one worker (timed), then the
    # cheaper one worker, except every PROBE_EVERY-th big launch
    assert picks[:4] == [2, 2, 1, 1]
    probes = [k for k, w in enumerate(picks) if w == 2 and k >= 4]
    assert len(probes) >= 2 and set(np.diff(probes)) == {stepping.PROBE_EVERY}
    assert many.cost(2) > stepping.TEAM_MARGIN * many.cost(1)
    many.timed(2, work, 1.1 * work * 1e-9)      # the team within the margin again
    assert many.workers_for(integrator, model, big) == 2


def test_a_team_has_no_more_workers_than_cores(threads, monkeypatch):
    """More pool threads than cores (threads= beyond the machine) must not make spinning
    workers wait for descheduled ones: one worker per core, here one, so no team."""
    monkeypatch.setattr(backend, "cpu_cores", lambda: 1)
    many = stepping.ManySteps(stepping.TeamStages())
    assert backend.cpu_threads() >= 2 and many.workers == 1


def test_a_team_without_threads_for_every_worker_raises_instead_of_hanging(threads, monkeypatch):
    cloth, start = sheet()
    sim = tc.Simulation(cloth, dt=2e-5)
    monkeypatch.setattr(team, "BARRIER_SPINS", 1 << 16)     # read when the kernel compiles
    many = stepping.ManySteps(sim.many_steps.stages)        # a kernel compiled here
    many.workers, many.adaptive = backend.cpu_threads() + 1, False
    monkeypatch.setattr(stepping, "TEAM_MIN_SPRING_STEPS", 0)
    monkeypatch.setattr(stepping, "TEAM_MIN_SPRINGS", 0)
    sim.set_positions(start)
    with pytest.raises(tc.TeamStalled, match="workers"):
        many.run(sim.integrator, sim.model, sim.state, sim.forces, sim.dt, 0, 50)


def test_every_stage_but_self_collision_runs_in_team_launches(f64):
    cloth, _ = sheet()
    assert tc.Simulation(cloth, dt=1e-4).many_steps is not None
    for kwargs in (dict(colliders=[tc.Plane(point=(0.0, -1.0, 0.0), normal=(0.0, 1.0, 0.0))]),
                   dict(strain_limit=tc.StrainLimit(max_strain=0.1)), dict(tearing=0.5),
                   dict(wind=tc.Wind(velocity=(1.0, 0.0, 0.0))),
                   dict(handles=[tc.Handle([0], lambda t: (0.0, 0.0, 0.0))])):
        assert tc.Simulation(cloth, dt=1e-4, **kwargs).many_steps is not None, kwargs
    with_contact = tc.Simulation(cloth, dt=1e-4, self_collision=tc.SelfCollision(
        thickness=0.01))
    assert with_contact.many_steps is not None      # its steps' heads (next test)
    with pytest.raises(ValueError, match="per stage"):
        with_contact.step(1, plan="many steps")
    wind = tc.Wind(velocity=(1.0, 0.0, 0.0))    # rk4's phases evaluate it at each RK stage
    assert tc.Simulation(cloth, integrator="rk4", dt=1e-4, wind=wind).many_steps is not None


def record_stages(monkeypatch):
    """Every stage's launch, by its STEP_ORDER name, in the order they run."""
    calls = []
    stages = {"integrator": (Integrator, "step"), "strain_limit": (StrainLimiter, "after_step"),
              "colliders": (ColliderSet, "after_step"), "handles": (HandleSet, "after_step"),
              "tearing": (tc.Tearing, "after_step")}
    for name, (owner, method) in stages.items():
        def wrapped(*args, _name=name, _original=getattr(owner, method)):
            calls.append(_name)
            return _original(*args)
        monkeypatch.setattr(owner, method, wrapped)
    return calls


@pytest.mark.parametrize("features", [
    ("strain_limit", "colliders", "handles", "tearing"), ("colliders", "tearing"), ("handles",), ()])
def test_a_step_runs_its_stages_in_step_order(f64, monkeypatch, features):
    """One launch per stage: the integrator, then exactly the stages the scene has, in
    STEP_ORDER; the many-steps plan runs each of them inside the launch (its `launched`
    object), in the same order (TeamStages.after)."""
    cloth, _ = sheet()
    options = {"strain_limit": dict(strain_limit=tc.StrainLimit(max_strain=0.1)),
               "colliders": dict(colliders=[tc.Plane(point=(0.0, -1.0, 0.0))]),
               "handles": dict(handles=[tc.Handle([0], lambda t: (0.0, 0.0, 0.0))]),
               "tearing": dict(tearing=0.5)}
    kwargs = {k: v for name in features for k, v in options[name].items()}
    sim = tc.Simulation(cloth, integrator="symplectic_euler", dt=1e-4, **kwargs)
    calls = record_stages(monkeypatch)
    for _ in range(3):
        sim.step(1, plan="per stage")
    expected = tuple(name for name in STEP_ORDER if name == "integrator" or name in features)
    assert sim.stages == expected
    assert calls == list(expected) * 3
    assert all(isinstance(sim.stage(name), Stage) for name in expected[1:])
    assert all(sim.stage(name) is None for name in STEP_ORDER[1:] if name not in expected)
    launched = sim.many_steps.stages.stages
    assert tuple(launched) == expected[1:]
    assert all(launched[name] is sim.stage(name).launched for name in launched)


def test_stages_are_kept_in_step_order_by_name():
    assert STEP_ORDER[0] == "integrator" and len(set(STEP_ORDER)) == len(STEP_ORDER)
    assert list(in_order({"tearing": 1, "handles": 2, "colliders": None})) == ["handles",
                                                                             "tearing"]
    with pytest.raises(KeyError, match="self_contact"):
        in_order({"self_contact": 1})


@pytest.mark.parametrize("integrator", FUSED)
def test_divergence_names_the_same_step_in_every_plan(threads, integrator, monkeypatch):
    cloth, start = sheet()
    steps = []
    sim = tc.Simulation(cloth, integrator=integrator, dt=5.0 * sim_stable(cloth, integrator))
    for plan in PLANS:
        sim.restart()
        sim.set_positions(start)
        with pytest.raises(tc.SimulationDiverged) as error:
            run(sim, plan, 5000, monkeypatch)
        steps.append(error.value.step)
    print(f"{integrator}: first bad step {steps}")
    assert len(set(steps)) == 1 and steps[0] < 5000


def sim_stable(cloth, integrator):
    return tc.stable_dt(cloth, "symplectic_euler" if integrator == "explicit_euler" else integrator)


@pytest.mark.parametrize("damping", ["axial", "relative"])
def test_two_phase_gather_matches_an_independent_scatter(f64, damping):
    """At a random state, each particle's force equals a numpy scatter of the per-spring
    formula (Stuyck eq. 4.5, 4.7) over every spring kind, to rounding."""
    rng = np.random.default_rng(3)
    body, _ = sheet(5, damping)
    model = Model(body)
    state = model.state()
    x = body.particle_position + 0.05 * rng.normal(size=(body.particle_count, 3))
    v = rng.normal(size=(body.particle_count, 3))
    state.particle_position.from_numpy(x)
    state.particle_velocity.from_numpy(v)
    compute_forces(model, state, ForceSettings(gravity=(0.0, 0.0, 0.0)))
    got = state.particle_force.to_numpy()

    i, j = body.spring_indices.T
    d = x[i] - x[j]
    length = np.linalg.norm(d, axis=1)
    n = d / length[:, None]
    dv = v[i] - v[j]
    damp = (body.spring_damping[:, None] * dv if damping == "relative"
            else (body.spring_damping * np.sum(dv * n, axis=1))[:, None] * n)
    f = -(body.spring_stiffness * (length - body.spring_rest_length))[:, None] * n - damp
    expected = np.zeros_like(x)
    np.add.at(expected, i, f)
    np.add.at(expected, j, -f)
    error = np.abs(got - expected).max()
    print(f"max |f - scatter| = {error:.3g} N of max |f| {np.abs(expected).max():.3g} N")
    assert error <= 1e-12 * np.abs(expected).max()
    assert abs(got.sum(axis=0)).max() <= 1e-12 * np.abs(expected).max(), "third law"


def load_benchmark():
    path = Path(__file__).parents[1] / "benchmarks" / "throughput.py"
    if str(path.parent) not in sys.path:
        sys.path.append(str(path.parent))           # its sibling modules (peers.py)
    spec = importlib.util.spec_from_file_location("throughput", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_benchmark_numpy_baseline_steps_like_ti_cloth(f64):
    """The baseline the README's speed-ups are quoted against computes the same step."""
    bench = load_benchmark()
    cloth, start = bench.scene(10)
    dt = tc.auto_dt(cloth, "explicit_euler")
    sim = tc.Simulation(cloth, dt=dt)
    sim.set_positions(start)
    baseline = bench.NumpyCloth(cloth, start, dt, (0.0, -9.81, 0.0), np.float64)
    sim.step(50)
    baseline.step(50)
    error = np.abs(baseline.velocities() - sim.velocities()).max()
    print(f"max |v_numpy - v_ti_cloth| = {error:.3g} of max |v| {np.abs(sim.velocities()).max():.3g}")
    assert error <= 1e-10 * np.abs(sim.velocities()).max()


def test_benchmark_runs_and_writes_its_table(tmp_path):
    bench = load_benchmark()
    out = tmp_path / "t.csv"
    bench.main(["--sizes", "6", "--precisions", "f64", "--integrators", "symplectic_euler", "pbd",
                "--seconds", "0.01", "--repeats", "1", "--csv", str(out)])
    text = out.read_text().splitlines()
    assert text[0].startswith("arch,precision,N,")
    assert [line.split(",")[5] for line in text[1:]] == ["ti_cloth symplectic_euler", "ti_cloth pbd", "numpy"]


def folding_scene(monkeypatch, plan):
    """Two sheets built 15 mm apart (farther than the 10 mm thickness at rest, so their pairs
    are contacts) and placed 8 mm apart (in contact from the first step), without gravity, a
    corner of the lower one drawn sideways by a handle, with a collider, tearing and
    self-collision, at symplectic Euler's 1e-4 s (its stable step 1.4e-4 s); its calls
    recorded by stage; `plan` "team" forces a team of two on every launch of a step's
    head."""
    mesh = tc.grid_mesh(8, 8, size=(0.5, 0.5), plane="xz")
    cloth = tc.Cloth.combine([tc.Cloth(tc.Mesh(mesh.vertices + shift, mesh.triangles),
                                       tc.Material())
                              for shift in ([0.0, 0.0, 0.0], [0.023, 0.015, 0.017])])
    sim = tc.Simulation(
        cloth, integrator="symplectic_euler", dt=1e-4, gravity=(0.0, 0.0, 0.0),
        colliders=[tc.Plane(point=(0.0, -0.3, 0.0))],
        handles=[tc.Handle([0], lambda t: (0.5 * t, 0.0, 0.0))], tearing=3.0,
        self_collision=tc.SelfCollision(thickness=0.01, friction=0.2))
    placed = cloth.particle_position.copy()
    placed[64:, 1] = 0.008
    sim.set_positions(placed)
    if plan == "team":
        monkeypatch.setattr(sim.many_steps, "adaptive", False)
        monkeypatch.setattr(sim.many_steps, "workers", 2)
        monkeypatch.setattr(stepping, "TEAM_MIN_SPRING_STEPS", 0)
        monkeypatch.setattr(stepping, "TEAM_MIN_SPRINGS", 0)
    return sim, record_stages(monkeypatch)


def test_with_self_collision_a_steps_head_is_one_team_launch_with_the_same_bits(
        threads, monkeypatch):
    """With self-collision, whose list is made on the host between steps, each step runs the
    integrator and the stages before self-collision (handles, colliders) in
    one team launch, then self-collision and tearing launch by launch: the order of
    STEP_ORDER, and the bits of a launch per stage (a team of two here; one worker runs
    the same kernel: team.py)."""
    steps = 40
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")    # started within the thickness: what is left, told
        sim, calls = folding_scene(monkeypatch, "team")
        sim.step(steps)
        assert calls == ["tearing"] * steps, "the head ran in the launch, tearing after it"
        teamed = sim.positions(), sim.velocities()
        del sim      # the pool lends its kernels to the next one (pool.py): one build of each
        staged, staged_calls = folding_scene(monkeypatch, "default")
        for _ in range(steps):
            staged.step(1, plan="per stage")
    height = teamed[0][:, 1]
    apart = np.median(height[64:]) - np.median(height[:64])
    assert apart > 0.009, f"the passes pushed the sheets from 8 mm to the thickness: {apart}"
    assert staged_calls == ["integrator", "handles", "colliders", "tearing"] * steps
    np.testing.assert_array_equal(teamed[0], staged.positions())
    np.testing.assert_array_equal(teamed[1], staged.velocities())


@ti.func
def _mark(marks: ti.template(), i):
    marks[i] = marks[i] + 1


class _Marking:
    """An owner of one phase: a loop over the items in use of a room of 8 (plan.Used)."""

    def __init__(self):
        self.used = ti.field(ti.i32, 1)
        self.marks = ti.field(ti.i32, 8)

    def phases(self, model, forces, work):
        return (runtime_plan.Phase(runtime_plan.Loop(runtime_plan.Used(self.used, 0, 8),
                                                     _mark, self.marks, runtime_plan.ITEM)),)


@pytest.mark.parametrize("serial", [True, False], ids=["serial launch", "launch per phase"])
def test_a_loop_counted_at_run_time_runs_over_the_items_in_use(f64, serial):
    """plan.Used: a loop over a list's pairs in use (self-contact's passes, the fail-safe) is
    as long as the list is now, read when the loop starts, within its room: items 0-2 of 8
    with 3 in use, then all 8 with 11 asked (a list grown for a dense moment no longer walks
    its empty room ever after). The serial launch runs a team's share (run_team)."""
    owner = _Marking()
    for used, expected in ((3, [1, 1, 1, 0, 0, 0, 0, 0]), (11, [2, 2, 2, 1, 1, 1, 1, 1])):
        owner.used[0] = used
        runtime_plan.run(owner, None, None, None, None, 0.01, 0, True, serial=serial)
        np.testing.assert_array_equal(owner.marks.to_numpy(), expected)
