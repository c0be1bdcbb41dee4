"""A scene's preview (app/scene_preview.py, `ti-cloth view --preview`): garment panels cut
coarser until they hold about PREVIEW_PARTICLES particles, position-based steps of at most
1/60 s, everything else as the file has it; the viewer says so on screen and saves its states
apart from the file's scene."""

from pathlib import Path

import numpy as np
import pytest

from ti_cloth.app.cli import build_parser
from ti_cloth.app.scene import load_scene
from ti_cloth.app.scene_preview import PREVIEW_PARTICLES, PREVIEW_STEP
from ti_cloth.app.view import viewer_for
from ti_cloth.inputs.scene_file import SceneError
from ti_cloth.render.viewer import TIP_AFTER, TIP_BELOW

SCENE = """
[simulation]
integrator = "{integrator}"
fps = 30
{steps}

[[bodies]]
type = "grid"
rows = 5
cols = 4
size = [0.3, 0.2]
origin = [1.0, 1.0, 0.0]
pinned = ["top_left"]

[[bodies]]
type = "garment"
fabric = "denim"
pinned = ["panel0_edge2"]

[[bodies.panels]]
outline = [[0.0, 0.0], [0.6, 0.0], [0.6, 0.4], [0.0, 0.4]]
edge_length = {edge}
translate = [0.0, 1.0, 0.0]
"""


def scene_text(integrator="xpbd", steps="substeps = 8", edge=0.01):
    return SCENE.format(integrator=integrator, steps=steps, edge=edge)


def write(tmp_path, text, name="scene.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def mean_edge(positions: np.ndarray, triangles: np.ndarray) -> float:
    """The mean length of the mesh's edges, each once (computed here, not by the package)."""
    ends = np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    ends = np.unique(ends, axis=0)
    return float(np.linalg.norm(positions[ends[:, 0]] - positions[ends[:, 1]], axis=1).mean())


def garment_part(scene, grid_count=20):
    """The garment's positions and triangles (the grid's 20 particles come first)."""
    x, triangles = scene.cloth.particle_position, scene.cloth.mesh.triangles
    mine = triangles[(triangles >= grid_count).all(axis=1)] - grid_count
    return x[grid_count:], mine


def test_a_preview_cuts_the_panels_to_its_budget_and_steps_xpbd_at_a_sixtieth(tmp_path):
    path = write(tmp_path, scene_text())
    scene, preview = load_scene(path), load_scene(path, preview=True)
    assert scene.preview == () and scene.resolved_substeps() == 8
    ratio = mean_edge(*garment_part(preview)) / mean_edge(*garment_part(scene))
    particles = preview.cloth.particle_count - 20
    print(f"mean garment edge, preview / file: {ratio:.3f}; garment particles {particles} "
          f"of {scene.cloth.particle_count - 20}")
    # the panel (0.24 m² at 1 cm: about 2,800 particles) cut at about 500, so its edges are
    # longer by about the square root of that ratio
    assert abs(particles - PREVIEW_PARTICLES) < 0.25 * PREVIEW_PARTICLES
    expected = np.sqrt((scene.cloth.particle_count - 20) / particles)
    assert abs(ratio - expected) < 0.15 * expected
    # the grid is as the file has it, and its pin
    np.testing.assert_array_equal(preview.cloth.particle_position[:20],
                                  scene.cloth.particle_position[:20])
    assert preview.cloth.pinned[:20].tolist() == scene.cloth.pinned[:20].tolist()
    # the garment's named edge is pinned at the new cut too: along the panel's top
    top = preview.cloth.particle_position[20:][preview.cloth.pinned[20:]]
    assert len(top) >= 8 and np.allclose(top[:, 1], 1.4)
    assert preview.resolved_substeps() == round(1 / (30 * PREVIEW_STEP)) == 2
    assert preview.preview == ("garment panels cut at 2.4 cm (the file's 1)",
                               "steps of 1/60 s (the file's: 1/240 s)")


def test_a_garment_within_the_budget_keeps_its_cut(tmp_path):
    path = write(tmp_path, scene_text(edge=0.04))      # about 170 particles
    scene, preview = load_scene(path), load_scene(path, preview=True)
    assert preview.cloth.particle_count == scene.cloth.particle_count
    assert preview.preview == ("steps of 1/60 s (the file's: 1/240 s)",)


@pytest.mark.parametrize("integrator, steps, changed", [
    ("symplectic_euler", "substeps = 8", None),     # its step is bounded by its stability
    ("implicit_euler", "substeps = 8", None),       # costs as much a simulated second
    ("xpbd", "substeps = 1", None),                 # never more steps than the file's
    ("xpbd", "dt = 0.002", "steps of 1/60 s (the file's: 1/510 s)"),
    ("xpbd", "", "steps of 1/60 s (the file's: auto)"),
])
def test_a_preview_steps_longer_only_where_a_position_based_step_is(tmp_path, integrator,
                                                                     steps, changed):
    path = write(tmp_path, scene_text(integrator, steps))
    file, preview = load_scene(path), load_scene(path, preview=True)
    assert preview.preview[1:] == ((changed,) if changed else ())
    if changed is None:
        assert preview.substeps == file.substeps
    else:
        assert preview.resolved_substeps() == 2


def test_a_preview_leaves_a_bad_value_for_the_reader_to_name(tmp_path):
    path = write(tmp_path, scene_text(edge=-0.01))
    with pytest.raises(SceneError, match=r"edge_length.*-0\.01"):
        load_scene(path, preview=True)


def test_the_viewer_of_a_preview_says_so_and_saves_apart(tmp_path, f64):
    path = write(tmp_path, scene_text())
    viewer = viewer_for(load_scene(path, preview=True), width=64, height=48, folder=tmp_path)
    viewer.advance()
    assert viewer.sim.dt == pytest.approx(1 / 60)
    assert viewer.status()[2] == ("preview: garment panels cut at 2.4 cm (the file's 1); "
                                  "steps of 1/60 s (the file's: 1/240 s)")
    assert viewer.save() == tmp_path / "scene_preview.view.npz"
    plain = viewer_for(load_scene(path), width=64, height=48, folder=tmp_path)
    assert len(plain.status()) == 2 and plain.name == "scene"
    # a file's scene run at a third of real time for TIP_AFTER suggests its preview (a grid
    # alone: the preview would change its steps)
    grid = write(tmp_path, "[[bodies]]".join(scene_text().split("[[bodies]]")[:2]), "grid.toml")
    plain = viewer_for(load_scene(grid), width=64, height=48, folder=tmp_path)
    tip = "tip: --preview: steps of 1/60 s (the file's: 1/240 s)"
    plain.tick(0.0)
    frames = int(TIP_AFTER / plain.frame_dt / 3) + 1
    for k in range(frames):
        plain.advance()
        plain.tick(3 * (k + 1) * plain.frame_dt)
        assert (tip in plain.status()) == (3 * (k + 1) * plain.frame_dt >= TIP_AFTER)
    for k in range(4 * frames):                    # then faster than real time: no tip
        plain.advance()
        plain.tick(3 * frames * plain.frame_dt + 0.5 * (k + 1) * plain.frame_dt)
    assert plain.simulated >= TIP_BELOW * plain.running and tip not in plain.status()
    assert build_parser().parse_args(["view", str(path), "--preview"]).preview


def test_a_preview_run_writes_its_frames_beside_the_files(tmp_path, monkeypatch, f64):
    """`ti-cloth run --preview` and a demo's --preview write into the output folder with
    `_preview` after its name, never over the file's frames and states."""
    from ti_cloth.app.cli import demo_main, main

    out = tmp_path / "out"
    text = scene_text(edge=0.04) + f'\n[output]\nwidth = 64\nheight = 48\nfolder = "{out}"\n'
    path = write(tmp_path, text)
    assert main(["run", str(path), "--preview", "--frames", "2", "--no-progress"]) == 0
    assert sorted(p.name for p in (tmp_path / "out_preview").glob("*.png"))[:2] == \
        ["frame_00000.png", "frame_00001.png"]
    assert not out.exists()
    monkeypatch.chdir(tmp_path)
    frames = demo_main(path, ["--preview", "--test", "--frames", "1", "--no-progress"])
    assert frames and frames[0].parent == Path("renders") / "scene_preview"


@pytest.mark.parametrize("folder, preview_folder", [("renders/cape", "renders/cape_preview"),
                                                    (".", "preview")])
def test_a_preview_is_named_apart_and_writes_beside_the_files_folder(tmp_path, folder,
                                                                      preview_folder):
    path = write(tmp_path, scene_text() + f'\n[output]\nfolder = "{folder}"\n')
    file, preview = load_scene(path), load_scene(path, preview=True)
    assert (file.name, preview.name) == ("scene", "scene_preview")
    assert preview.output.folder == Path(preview_folder)
