"""Saved states and resumed runs (Simulation.save_state / load_state, `ti-cloth run --resume`):
a simulation loaded from a state continues with the same bits as one never stopped, a run
killed with SIGKILL and resumed writes the same bytes (frames, GIF, OBJ, PLY, PC2, npz, USD),
and a state from another simulation or format is refused."""

import gc
import json
import os
import signal
import subprocess
import sys
import time
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from helpers import twisted_sheet, wound_twist
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import ti_cloth as tc
from ti_cloth.app import cli
from ti_cloth.errors import StateMismatch
from ti_cloth.export import Exporter

SAVE_AT, STEPS = 40, 80          # steps of 1/240 s: the upper sheet lands at about step 25


def two_sheets(integrator: str, gravity=(0.0, -9.81, 0.0)) -> tc.Simulation:
    """A sheet dropped 3 cm onto a sheet pinned at its corners (self-collision), over a sphere
    moving along a path, in wind, tearable (but with tethers, which refuse it), one corner
    held by a handle until t = 0.1 s."""
    lower = tc.Cloth(tc.grid_mesh(8, 8, size=(0.4, 0.4), plane="xz"), tc.Material(),
                     pinned=[0, 7, 56, 63])
    upper = tc.Cloth(tc.grid_mesh(8, 8, size=(0.3, 0.3), plane="xz", origin=(0.05, 0.03, 0.05)),
                     tc.Material())
    cloth = tc.Cloth.combine([lower, upper])
    return tc.Simulation(
        cloth, integrator=integrator, dt=1 / 240, gravity=gravity,
        tearing=None if getattr(integrator, "tethers", None) is not None else 0.5,
        wind=tc.Wind(velocity=(0.5, 0.0, 0.0), turbulence=0.3),
        handles=[tc.Handle([64], lambda t: (0.0, 0.0, 0.0), release=0.1)],
        colliders=[tc.Sphere(centre=(0.2, -0.2, 0.2), radius=0.1,
                             path=tc.Oscillation((0.05, 0.0, 0.0), 2.0))],
        self_collision=tc.SelfCollision(thickness=0.01))


def outcome(sim) -> dict:
    return {"x": sim.positions(), "v": sim.velocities(), "torn": sim.spring_torn_step(),
            "pinned": sim.pinned()}


def assert_same_bits(a: dict, b: dict) -> None:
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


@pytest.mark.parametrize("integrator", ["xpbd", "pbd", "tr_bdf2", tc.XPBD(scheme="bdf2"),
                                        tc.XPBD(scheme="bdf2", tethers=1e-3)],
                         ids=["xpbd", "pbd", "tr_bdf2", "xpbd bdf2", "xpbd tethered"])
def test_a_loaded_state_continues_with_the_same_bits(f64, tmp_path, integrator):
    """Saved at step 40 (the sheets in contact, the handle let go), loaded into a new
    simulation and stepped to 80: positions, velocities, tear steps and pins equal those of
    the run never stopped, bit for bit, and the loaded self-collision list is the saved one.
    Positions and velocities alone (set_positions / set_velocities) are not enough: the
    handle holds again, the sphere and the wind start over - other bits."""
    sim = two_sheets(integrator)
    sim.step(SAVE_AT)
    touching = sim.self_contacts()
    assert len(touching.vertex_triangle) + len(touching.edge_edge) > 0   # in contact
    assert not sim.pinned()[64]                                          # let go
    listed = sim.self_contacts(active=False)
    saved = outcome(sim)
    sim.save_state(tmp_path / "state.npz")
    sim.step(STEPS - SAVE_AT)
    expected = outcome(sim)
    del sim
    gc.collect()                       # its fields and kernels go to the next one (pool.py)
    resumed = two_sheets(integrator)
    assert resumed.pinned()[64]        # held at the start
    resumed.load_state(tmp_path / "state.npz")
    assert resumed.step_count == SAVE_AT and resumed.time == SAVE_AT / 240
    again = resumed.self_contacts(active=False)
    for key in ("vertex_triangle", "edge_edge"):
        np.testing.assert_array_equal(getattr(again, key), getattr(listed, key))
        np.testing.assert_array_equal(getattr(resumed.self_contacts(), key),
                                      getattr(touching, key))
    assert resumed.self_contacts().passes == touching.passes > 0
    resumed.step(STEPS - SAVE_AT)
    assert_same_bits(expected, outcome(resumed))
    resumed.restart()
    resumed.set_positions(saved["x"])
    resumed.set_velocities(saved["v"])
    resumed.step(STEPS - SAVE_AT)
    assert not np.array_equal(resumed.positions(), expected["x"])


def test_a_state_saved_after_its_list_was_made_again_reports_that_steps_contacts(f64, tmp_path):
    """Where the passes of a step moved the cloth past its list, the list is made again after
    them and the step's contacts are those of the list they were found on (self_collision.py).
    A 12 x 12 sheet twisted three half turns a second does so at step 37: saved there and
    loaded, self_contacts() reports the same pairs in contact and passes (the new list's
    flags hold none of them: without the rows saved it reported none), and 8 more steps
    give the bits of the run never stopped."""
    body, handles, _ = twisted_sheet(n=12, size=0.6, turns=3.0)

    def twist():
        return tc.Simulation(body, integrator="xpbd", dt=1 / 240, handles=handles,
                             gravity=(0.0, 0.0, 0.0),
                             self_collision=tc.SelfCollision(thickness=0.005))
    sim = twist()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")        # the passes' reports of a tight twist
        sim.step(37)
        assert sim.self_collision.step_contacts is not None, "made again after the passes"
        saved = sim.self_contacts()
        assert len(saved.vertex_triangle) > 0 and len(saved.edge_edge) > 0
        sim.save_state(tmp_path / "twist.npz")
        sim.step(8)
        resumed = twist()
        resumed.load_state(tmp_path / "twist.npz")
        loaded = resumed.self_contacts()
        for key in ("vertex_triangle", "edge_edge"):
            np.testing.assert_array_equal(getattr(loaded, key), getattr(saved, key))
        assert loaded.passes == saved.passes
        resumed.step(8)
    np.testing.assert_array_equal(resumed.positions(), sim.positions())
    np.testing.assert_array_equal(resumed.velocities(), sim.velocities())


def test_many_steps_per_launch_resume_on_the_same_bits(f64, tmp_path):
    """A sheet without stages runs many steps per launch (integrators/fused.py): saved after
    3 calls of step(16), loaded and stepped 3 more, it equals 6 calls of one run."""
    def sheet():
        return tc.Simulation(tc.Cloth(tc.grid_mesh(10, 10), tc.Material(), pinned=[0, 9]),
                             integrator="symplectic_euler", dt="auto")

    sim = sheet()
    for call in range(6):
        sim.step(16)
        if call == 2:
            sim.save_state(tmp_path / "state.npz")
    expected = outcome(sim)
    del sim
    gc.collect()
    resumed = sheet()
    resumed.load_state(tmp_path / "state.npz")
    for _ in range(3):
        resumed.step(16)
    assert_same_bits(expected, outcome(resumed))


def test_a_state_of_another_simulation_or_format_is_refused(f64, tmp_path):
    sim = tc.Simulation(tc.Cloth(tc.grid_mesh(4, 4), tc.Material(), pinned=[0]), dt=1e-3)
    sim.step(3)
    path = sim.save_state(tmp_path / "state.npz")
    for other in (tc.Simulation(tc.Cloth(tc.grid_mesh(4, 4), tc.Material(), pinned=[0]), dt=2e-3),
                  tc.Simulation(tc.Cloth(tc.grid_mesh(4, 4), tc.Material(density=0.3),
                                         pinned=[0]), dt=1e-3),
                  tc.Simulation(tc.Cloth(tc.grid_mesh(4, 4), tc.Material(), pinned=[0]),
                                dt=1e-3, gravity=(0.0, -9.8, 0.0))):
        with pytest.raises(StateMismatch, match="different simulation"):
            other.load_state(path)
    with zipfile.ZipFile(path) as archive:            # the same file, another format number
        members = {name: archive.read(name) for name in archive.namelist()}
    header = np.load(path)["header"]
    changed = json.loads(str(header)) | {"format": 0}
    np.save(tmp_path / "header.npy", np.array(json.dumps(changed)))
    members["header.npy"] = (tmp_path / "header.npy").read_bytes()
    with zipfile.ZipFile(tmp_path / "old.npz", "w") as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    with pytest.raises(StateMismatch, match="format 0"):
        sim.load_state(tmp_path / "old.npz")
    (tmp_path / "text.npz").write_text("not a state")
    with pytest.raises(StateMismatch, match="not a ti_cloth saved state"):
        sim.load_state(tmp_path / "text.npz")
    whole = path.read_bytes()                        # cut short: a copy stopped half-way
    for size in (len(whole) // 2, len(whole) - 30, 100):
        (tmp_path / "cut.npz").write_bytes(whole[:size])
        with pytest.raises(StateMismatch, match="cut.npz is damaged"):
            sim.load_state(tmp_path / "cut.npz")
    with pytest.raises(FileNotFoundError, match="saved state not found"):
        sim.load_state(tmp_path / "absent.npz")
    sim.load_state(path)                             # its own state still loads
    assert sim.step_count == 3


class LaterXPBD(tc.XPBD):
    """XPBD as a later version might have it: an option more, whose default keeps the motion."""

    def __init__(self, *, later: float = 0.0, **options):
        super().__init__(**options)
        self.later = later

    def options(self):
        return super().options() | {"later": self.later}


def test_a_state_saved_before_an_option_was_added_still_loads(f64, tmp_path):
    """The fingerprint holds the integrator's options that were given away from their
    defaults (Integrator.changed_options): a state saved by XPBD loads into a simulation of
    an XPBD with an option more at its default (and one that names an existing option at its
    default), and is refused by one whose new option is not at its default, or whose passes
    differ. Fed every option, as before, each new option refused every xpbd state saved
    before it (membrane_relaxation, scheme)."""
    def sim(integrator):
        return tc.Simulation(tc.Cloth(tc.grid_mesh(4, 4), tc.Material(), pinned=[0]),
                             integrator=integrator, dt=1e-3)
    first = sim(tc.XPBD())
    first.step(3)
    path = first.save_state(tmp_path / "state.npz")
    for same in (LaterXPBD(), tc.XPBD(membrane_relaxation=1.0, scheme="backward_euler")):
        loaded = sim(same)
        loaded.load_state(path)
        assert loaded.step_count == 3
    for other in (LaterXPBD(later=1.0), tc.XPBD(iterations=4)):
        with pytest.raises(StateMismatch, match="different simulation"):
            sim(other).load_state(path)


def test_an_exporter_resumes_only_on_a_journal_that_holds_the_frames(f64, tmp_path):
    cloth = tc.Cloth(tc.grid_mesh(3, 3), tc.Material(), pinned=[0])
    sim = tc.Simulation(cloth, dt=1e-3)
    export = Exporter(tmp_path, ["pc2"], name="s", cloth=cloth, fps=30)
    for _ in range(3):
        export.write(sim)
    export.close(keep_journal=True)
    with pytest.raises(StateMismatch, match="holds 3 frames, the saved state needs 5"):
        Exporter(tmp_path, ["pc2"], name="s", cloth=cloth, fps=30, first_frame=5)
    with pytest.raises(StateMismatch, match="other formats"):
        Exporter(tmp_path, ["pc2", "npz"], name="s", cloth=cloth, fps=30, first_frame=2)


SCENE = """
[scene]
name = "resume"
[simulation]
integrator = "xpbd"
fps = 30
duration = 0.7
substeps = 4
precision = "f64"
tearing = 0.5
[forces]
wind = { velocity = [0.5, 0, 0], turbulence = 0.3 }
[[bodies]]
type = "grid"
rows = 10
cols = 10
size = [0.5, 0.5]
plane = "xz"
origin = [-0.25, 0.3, -0.25]
[[bodies.handles]]
particles = [0]
path = { type = "keyframes", times = [0.0, 1.0], values = [[0, 0, 0], [0, 0.2, 0]] }
release = 0.5
[[colliders]]
type = "sphere"
centre = [0.0, 0.1, 0.0]
radius = 0.12
path = { type = "oscillation", amplitude = [0.05, 0, 0], frequency = 1.0 }
[camera]
position = [0.8, 0.7, 1.0]
target = [0.0, 0.1, 0.0]
[output]
width = 64
height = 48
supersample = 1
"""
ARGUMENTS = ["--checkpoint-every", "5", "--export", "obj,ply,pc2,npz,usd", "--no-progress"]


@pytest.mark.slow
def test_a_run_killed_with_sigkill_and_resumed_writes_the_same_bytes(tmp_path, capsys):
    """One run never stopped; another killed (SIGKILL: no handler runs) after its state was
    saved at frame 5 or later, then `--resume`d: every file in the two folders is the same
    bytes (PNG frames, GIF, per-frame OBJ / PLY, PC2 caches, npz, USD, the saved state), and
    no journal or temporary file is left. A changed scene's state is refused (exit 2)."""
    scene = tmp_path / "resume.toml"
    scene.write_text(SCENE)
    whole, killed = tmp_path / "whole", tmp_path / "killed"
    assert cli.main(["run", str(scene), "--out", str(whole), *ARGUMENTS]) == 0
    command = [sys.executable, "-m", "ti_cloth.app.cli", "run", str(scene), "--out", str(killed),
               *ARGUMENTS]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               env={**os.environ, "PYTHONPATH": str(Path(tc.__file__).parents[1])})
    deadline = time.monotonic() + 120
    while not (killed / "frame_00008.png").is_file() and time.monotonic() < deadline:
        assert process.poll() is None, "the run ended before it could be killed"
        time.sleep(0.02)
    process.send_signal(signal.SIGKILL)
    process.wait()
    written = sorted(p.name for p in killed.glob("frame_*.png"))
    assert 9 <= len(written) < 21 and (killed / ".resume.journal").is_file()
    capsys.readouterr()
    assert cli.main(["run", str(scene), "--out", str(killed), "--resume", *ARGUMENTS]) == 0
    assert "resumed at frame " in capsys.readouterr().out
    names = sorted(p.name for p in whole.iterdir())
    assert names == sorted(p.name for p in killed.iterdir())
    assert len([n for n in names if n.startswith("frame_")]) == 21 and "resume.usdc" in names
    assert not [n for n in names if n.startswith(".")]
    for name in names:
        assert (whole / name).read_bytes() == (killed / name).read_bytes(), name
    scene.write_text(SCENE.replace("tearing = 0.5", "tearing = 0.6"))
    assert cli.main(["run", str(scene), "--out", str(killed), "--resume", *ARGUMENTS]) == 2
    assert "different simulation" in capsys.readouterr().err
    scene.write_text(SCENE)                          # a state cut short (issue 40): refused
    state = killed / "resume.state.npz"
    state.write_bytes(state.read_bytes()[:state.stat().st_size // 2])
    assert cli.main(["run", str(scene), "--out", str(killed), "--resume", *ARGUMENTS]) == 2
    err = capsys.readouterr().err
    assert str(state) in err and "damaged" in err and "without --resume" in err
    assert "Traceback" not in err


def _corrupted(saved: Path, target: Path, kind: str, k: int) -> None:
    """`saved` rewritten to `target` with one corruption of `kind` (k picks where)."""
    with np.load(saved, allow_pickle=False) as data:
        arrays = {key: data[key] for key in data.files}
    header = json.loads(str(arrays["header"]))
    position = arrays["state.particle_position"]
    names = sorted(key for key in arrays if key != "header")
    if kind == "nan":
        position[k % len(position), k % 3] = np.nan
    elif kind == "far":
        position[k % len(position)] = 1e30
    elif kind == "missing":
        del arrays[names[k % len(names)]]
    elif kind == "length":
        arrays["state.particle_velocity"] = arrays["state.particle_velocity"][:-1 - k % 3]
    elif kind == "dtype":
        arrays["state.particle_velocity"] = arrays["state.particle_velocity"].astype(np.float32)
    elif kind == "steps":
        header["step_count"] = [-5, "12", 2**40, None][k % 4]
    elif kind == "header":
        arrays["header"] = np.array(["[1, 2]", "not json", "{\"format\": "][k % 3])
    if kind != "header":
        arrays["header"] = np.array(json.dumps(header))
    if kind == "forged":
        del arrays["state.spring_force"]          # written below, forged
    with open(target, "wb") as file:
        np.savez(file, **arrays)
    if kind == "forged":          # an .npy header claiming a huge array over a few bytes
        with zipfile.ZipFile(target, "a") as archive:
            head = "{'descr': '<f8', 'fortran_order': False, 'shape': (100000, 100000, 3), }"
            head = head.ljust(118) + "\n"
            archive.writestr("state.spring_force.npy",
                             b"\x93NUMPY\x01\x00" + len(head).to_bytes(2, "little")
                             + head.encode() + b"\0" * 16)


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(kind=st.sampled_from(["nan", "far", "missing", "length", "dtype", "steps", "header",
                             "forged"]),
       k=st.integers(0, 1000))
def test_a_corrupted_saved_state_is_refused_naming_what_is_wrong(f64, tmp_path_factory, kind, k):
    """Every corruption of a state whose fingerprint matches (non-finite or far positions, a
    missing array, a wrong length or dtype, a bad step count or header, an .npy header claiming
    100 GB) is a StateMismatch before anything is loaded: the simulation keeps its state."""
    folder = tmp_path_factory.mktemp("corrupt")
    cloth = tc.Cloth(tc.grid_mesh(4, 4, size=(0.3, 0.3)), tc.Material(), pinned=[12, 15])
    sim = tc.Simulation(cloth, integrator="verlet", dt=1e-3)
    sim.step(5)
    saved = sim.save_state(folder / "good.npz")
    before = sim.positions()
    _corrupted(saved, folder / "bad.npz", kind, k)
    with pytest.raises(StateMismatch):
        sim.load_state(folder / "bad.npz")
    np.testing.assert_array_equal(sim.positions(), before)


def _nth(names: list, k: int) -> str:
    """The k-th of `names` in sorted order, k taken modulo their count."""
    return sorted(names)[k % len(names)]


CONTACT_CORRUPTIONS = {
    "capacity": lambda a, k: a.__setitem__("self_contact.capacity", np.array(2**40)),
    "total": lambda a, k: a.__setitem__("self_contact.pair_total",
                                        a["self_contact.capacity"] + 1 + k),
    "vertex pairs": lambda a, k: a.__setitem__("self_contact.vertex_pairs", np.array(-1 - k)),
    "listed": lambda a, k: a.__setitem__("self_contact.listed", np.array(1.5)),
    "skin": lambda a, k: a.__setitem__("self_contact.skin", np.array(0.5 + k)),
    "missing": lambda a, k: a.pop(_nth([n for n in a if n.startswith("self_contact.")], k)),
    "index": lambda a, k: a["self_contact.particles"].__setitem__(
        (k % len(a["self_contact.particles"]), k % 4), 10**6),
    "falling": lambda a, k: a["self_contact.pair_start"].__setitem__(
        1 + k % (len(a["self_contact.pair_start"]) - 1), -1),
    "nan": lambda a, k: a["self_contact.listed_at"].__setitem__(
        (k % len(a["self_contact.listed_at"]), 0), np.nan),
    "length": lambda a, k: a.__setitem__("self_contact.active", a["self_contact.active"][:-1]),
    "dtype": lambda a, k: a.__setitem__("self_contact.elements",
                                        a["self_contact.elements"].astype(np.int64)),
    "passes": lambda a, k: a.__setitem__("self_contact.passes", np.array(17 + k)),
    "step rows": lambda a, k: a.__setitem__("self_contact.step_vertex_triangle",
                                            np.array([[0, 10**6 + k]], np.int32)),
}


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(kind=st.sampled_from(sorted(CONTACT_CORRUPTIONS)), k=st.integers(0, 1000))
def test_a_corrupted_self_contact_list_is_refused_before_anything_is_loaded(
        f64, tmp_path_factory, kind, k):
    """The self-collision candidate list of a saved state is checked array by array (its
    counts in range: a capacity of 2^40 would allocate without bound, an index out of the
    body would read out of the fields) before the state or the list is touched."""
    folder = tmp_path_factory.mktemp("contact")
    cloth = tc.Cloth(tc.grid_mesh(6, 6, size=(0.2, 0.2), plane="xz"), tc.Material())
    sim = tc.Simulation(cloth, integrator="symplectic_euler", dt=5e-4,
                        self_collision=tc.SelfCollision(thickness=0.05))
    sim.step(3)
    saved = sim.save_state(folder / "good.npz")
    before = sim.positions()
    with np.load(saved, allow_pickle=False) as data:
        arrays = {key: data[key].copy() for key in data.files}
    assert int(arrays["self_contact.pair_total"]) > 0       # the list holds pairs to corrupt
    CONTACT_CORRUPTIONS[kind](arrays, k)
    with open(folder / "bad.npz", "wb") as file:
        np.savez(file, **arrays)
    with pytest.raises(StateMismatch, match="self_contact|missing"):
        sim.load_state(folder / "bad.npz")
    np.testing.assert_array_equal(sim.positions(), before)
    sim.load_state(saved)                                    # the good one still loads


def test_a_run_loaded_at_every_step_keeps_the_bits_of_the_run(f32, tmp_path):
    """Self-contact's passes mark again only the pairs of particles that moved, across steps
    while the list lasts (self_collision.py, near pairs); a loaded state does not save the
    marks, and marks every pair in its first pass. A 24 x 24 sheet (0.6 m, 5 mm thickness,
    keep_thickness) twisted a half turn a second each way, saved and loaded again at every
    step from step 150, where it winds onto itself: every step of the loaded run marks
    every pair, and it ends each step on the bits of the run that did not."""
    run, loaded = wound_twist(), wound_twist()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")        # the passes' reports of a tight twist
        run.step(150)
        run.save_state(tmp_path / "twist.npz")
        for _ in range(60):
            loaded.load_state(tmp_path / "twist.npz")
            loaded.step(1)
            run.step(1)
            np.testing.assert_array_equal(loaded.positions(), run.positions())
            run.save_state(tmp_path / "twist.npz")
    assert run.self_contacts().passes > 1            # in contact, in many passes
