"""A file that cannot be written (issue 40: a full disk, a folder without permission, a
read-only file system) stops `ti-cloth run` with a message naming the file and the reason, exit
74, every finished frame and the last good checkpoint kept and nothing half-written under a
final name; the writer is made to fail here (a real disk is not filled)."""

import errno
import json
import os
import pathlib

import imageio.v3 as iio
import numpy as np
import pytest

import ti_cloth as tc
from ti_cloth.app import cli
from ti_cloth.render import image

SCENE = """
[scene]
name = "full"
[simulation]
integrator = "xpbd"
fps = 30
duration = 0.3
substeps = 4
precision = "f64"
[[bodies]]
type = "grid"
rows = 6
cols = 6
size = [0.3, 0.3]
plane = "xz"
origin = [-0.15, 0.2, -0.15]
pinned = [0, 5]
[camera]
position = [0.6, 0.5, 0.8]
target = [0.0, 0.1, 0.0]
[output]
width = 48
height = 32
supersample = 1
formats = ["png", "gif"]
"""
ARGUMENTS = ["--checkpoint-every", "3", "--export", "obj,pc2", "--no-progress"]


def failing(monkeypatch, name: str, code: int, where: str, nth: int = 1) -> None:
    """Make the `nth` and later writes of the file called `name` fail with `code`: inside the
    writer (imageio, for images) or when it is renamed into place (every other file)."""
    cause = OSError(code, os.strerror(code))
    seen = []

    def refused(path) -> bool:
        if pathlib.Path(path).name.replace(".tmp", "").lstrip(".") != name:
            return False
        seen.append(path)
        return len(seen) >= nth

    if where == "writer":
        write = iio.imwrite

        def imwrite(path, *args, **kwargs):
            if refused(path):
                raise cause
            return write(path, *args, **kwargs)

        monkeypatch.setattr(image.iio, "imwrite", imwrite)
    else:
        rename = pathlib.Path.replace

        def replace(self, target):
            if refused(target):
                raise cause
            return rename(self, target)

        monkeypatch.setattr(pathlib.Path, "replace", replace)


@pytest.mark.parametrize("name, code, where, nth, frames", [
    ("frame_00007.png", errno.ENOSPC, "writer", 1, 7),
    ("full.state.npz", errno.EROFS, "rename", 2, 7),    # the checkpoint of frame 6
    ("full_body0_00005.obj", errno.EACCES, "rename", 1, 6),   # after frame 5's image
    ("full.gif", errno.ENOSPC, "writer", 1, 9),
])
def test_a_file_that_cannot_be_written_stops_the_run_and_keeps_what_was_finished(
        tmp_path, capsys, monkeypatch, name, code, where, nth, frames):
    """The run stops at the file (exit 74) saying its path, the system's reason and what to
    do; the frames finished before it are kept (and, but for the GIF itself, the GIF holds
    them); the last checkpoint written whole is the one left (frame 3 when frame 6's fails),
    no temporary file is left, and `--resume` once the disk takes writes again finishes the
    run from that checkpoint."""
    scene = tmp_path / "full.toml"
    scene.write_text(SCENE)
    out = tmp_path / "out"
    with monkeypatch.context() as patch:
        failing(patch, name, code, where, nth)
        assert cli.main(["run", str(scene), "--out", str(out), *ARGUMENTS]) == 74
    err = capsys.readouterr().err
    assert f"cannot write {out / name}" in err and os.strerror(code) in err
    assert errno.errorcode[code] in err and "Traceback" not in err
    written = sorted(p.name for p in out.glob("frame_*.png"))
    assert written == [f"frame_{k:05d}.png" for k in range(frames)]
    assert f"{frames} finished frames kept" in err
    assert (out / name).exists() == (nth > 1)          # the earlier checkpoint, or nothing
    assert not [p.name for p in out.iterdir() if p.name.startswith(".") and ".tmp" in p.name]
    for path in out.glob("frame_*.png"):
        assert iio.imread(path).shape[:2] == (32, 48)
    if name != "full.gif":
        assert len(iio.imread(out / "full.gif", index=None)) == frames
    last = {"frame_00007.png": 6, "full.state.npz": 3, "full_body0_00005.obj": 3, "full.gif": 8}[name]
    header = json.loads(str(np.load(out / "full.state.npz")["header"]))
    assert header["step_count"] == last * 4
    assert f"the last checkpoint is {out / 'full.state.npz'}" in err
    assert cli.main(["run", str(scene), "--out", str(out), "--resume", *ARGUMENTS]) == 0
    assert len(list(out.glob("frame_*.png"))) == 9
    assert len(iio.imread(out / "full.gif", index=None)) == 9


def test_a_write_refused_by_the_system_is_an_output_error_naming_the_file(tmp_path,
                                                                         monkeypatch):
    """The API says the same: Simulation.save_state into a read-only place raises
    tc.OutputError (an OSError) naming the file and the reason, and leaves the file that was
    there as it was."""
    sim = tc.Simulation(tc.Cloth(tc.grid_mesh(3, 3, (0.1, 0.1)), tc.Material()))
    path = tmp_path / "state.npz"
    sim.save_state(path)
    before = path.read_bytes()
    sim.step(3)
    failing(monkeypatch, "state.npz", errno.EROFS, "rename")
    with pytest.raises(tc.OutputError, match=f"cannot write {path}: Read-only file system "
                                             r"\(EROFS\); choose a folder on a writable"):
        sim.save_state(path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["state.npz"]
