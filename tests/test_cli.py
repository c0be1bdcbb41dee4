"""The ti-cloth command: run, info, strict arguments, Ctrl-C, SIGTERM and divergence."""

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from ti_cloth.app import cli
from ti_cloth.app.scene import Scene
from ti_cloth.render import image
from ti_cloth.simulation import Simulation

# the runs here initialise Taichi in their scenes' precision, f32: among the f32 tests
# (conftest), they do not switch a worker out of f64 and back
pytestmark = pytest.mark.usefixtures("f32")

SCENE = """
[scene]
name = "tiny"
[simulation]
fps = 30
duration = 1.0
[[bodies]]
type = "grid"
rows = 5
cols = 5
pinned = ["top_left", "top_right"]
[output]
width = 96
height = 64
supersample = 1
"""


@pytest.fixture
def scene(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(SCENE)
    return path


def frames_in(folder):
    return sorted(Path(folder).glob("frame_*.png"))


def test_run_writes_the_requested_frames_and_a_gif(scene, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli.main(["run", str(scene), "--out", str(out), "--frames", "3", "--no-progress"]) == 0
    assert len(frames_in(out)) == 3 and (out / "tiny.gif").is_file()
    assert "3 frames of 'tiny'" in capsys.readouterr().out


def test_run_writes_an_mp4_of_every_frame_with_mp4(scene, tmp_path, capsys, monkeypatch):
    """ti-cloth run --mp4 (no longer only the demo scripts'): the MP4 read back holds every
    frame written. Without imageio-ffmpeg it exits 2 naming the extra, before Taichi runs."""
    import imageio.v3 as iio

    out = tmp_path / "out"
    assert cli.main(["run", str(scene), "--out", str(out), "--frames", "4", "--mp4",
                     "--no-progress"]) == 0
    assert len(frames_in(out)) == 4
    assert sum(1 for _ in iio.imiter(out / "tiny.mp4")) == 4
    real = cli.importlib.util.find_spec
    monkeypatch.setattr(cli.importlib.util, "find_spec",
                        lambda name: None if name == "imageio_ffmpeg" else real(name))
    assert cli.main(["run", str(scene), "--out", str(tmp_path / "o2"), "--mp4"]) == 2
    assert 'pip install ".[video]"' in capsys.readouterr().err
    assert not (tmp_path / "o2").exists()
    assert cli.main(["view", str(scene), "--mp4"]) == 2


def test_run_exports_the_formats_of_the_flag_or_the_scene(scene, tmp_path, capsys):
    """--export obj,npz writes an OBJ per frame and the npz beside the PNGs; without the flag
    the scene's [output] formats decide (here "pc2")."""
    out = tmp_path / "out"
    assert cli.main(["run", str(scene), "--out", str(out), "--frames", "2", "--no-progress",
                     "--export", "obj,npz"]) == 0
    assert sorted(p.name for p in out.glob("tiny_*")) == ["tiny_body0_00000.obj",
                                                          "tiny_body0_00001.obj"]
    assert (out / "tiny.npz").is_file() and "+ 3 geometry files" in capsys.readouterr().out
    scene.write_text(SCENE.replace("supersample = 1", 'supersample = 1\nformats = ["png", "pc2"]'))
    assert cli.main(["run", str(scene), "--out", str(out), "--frames", "2", "--no-progress"]) == 0
    assert (out / "tiny_body0.pc2").is_file() and (out / "tiny_body0_rest.obj").is_file()
    scene.write_text(SCENE.replace("supersample = 1", 'supersample = 1\nformats = ["png", "fbx"]'))
    assert cli.main(["run", str(scene), "--no-progress"]) == 2
    assert 'output.formats must be a list of "png" (always)' in capsys.readouterr().err


@pytest.mark.parametrize("command", [["run"], ["study"], ["advise", "--tolerance", "0.1"],
                                     ["view"]])
@pytest.mark.parametrize("where", ["file", "under a file"])
def test_an_out_that_is_a_file_exits_74_naming_it(scene, tmp_path, capsys, command, where):
    """--out that is a file, or lies under one, is refused before anything runs (exit 74,
    sysexits' EX_IOERR), naming the file, for every command that writes."""
    blocker = tmp_path / "taken"
    blocker.write_text("not a folder")
    out = blocker if where == "file" else blocker / "frames"
    assert cli.main([command[0], str(scene), "--out", str(out), *command[1:]]) == 74
    assert f"{blocker} is a file, not a folder" in capsys.readouterr().err
    assert blocker.read_text() == "not a folder"


def test_bad_scene_exits_2_naming_the_key(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(SCENE.replace("rows = 5", "rows = 5\nrowz = 5"))
    assert cli.main(["run", str(bad), "--no-progress"]) == 2
    assert "bodies[0].rowz is not a known key" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["run"], ["run", "x.toml", "--frames", "0"], ["run", "x.toml", "--bogus"],
                                  ["run", "x.toml", "--arch", "tpu"], ["frobnicate"],
                                  ["run", "x.toml", "--export", "obj,fbx"],
                                  ["study", "x.toml", "--dt", "0"],
                                  ["study", "x.toml", "--dt", "nan"],
                                  ["study", "x.toml", "--duration", "inf"],
                                  ["advise", "x.toml", "--tolerance", "1e-3", "--window", "-1"]])
def test_arguments_are_parsed_strictly(argv):
    with pytest.raises(SystemExit) as err:
        cli.main(argv)
    assert err.value.code == 2


def test_sigterm_keeps_every_finished_frame_and_the_gif(scene, tmp_path, capsys, monkeypatch):
    """SIGTERM (as `timeout` sends it) in the third step call ends the run like Ctrl-C: the
    frames drawn so far stay, with no temporaries, and exit code 143; a Ctrl-C while the GIF is
    written is held until the GIF is complete. (Without the handlers SIGTERM kills the process
    and the GIF's Ctrl-C escapes as a KeyboardInterrupt traceback.)"""
    calls = {"n": 0}
    original_step, original_gif = Simulation.step, image.write_gif

    def interrupted_step(self, n=1):
        calls["n"] += 1
        if calls["n"] == 3:
            signal.raise_signal(signal.SIGTERM)
        original_step(self, n)

    def interrupted_gif(*args, **kwargs):
        signal.raise_signal(signal.SIGINT)
        return original_gif(*args, **kwargs)

    monkeypatch.setattr(Simulation, "step", interrupted_step)
    monkeypatch.setattr(image, "write_gif", interrupted_gif)
    out = tmp_path / "out"
    assert cli.main(["run", str(scene), "--out", str(out), "--no-progress"]) == 143
    assert len(frames_in(out)) == 3 and (out / "tiny.gif").is_file()
    assert not list(out.glob(".*"))                        # no half-written temp files
    assert "interrupted: 3 frames" in capsys.readouterr().err
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL   # handlers restored


def test_a_stop_signal_before_the_first_frame_exits_cleanly(scene, tmp_path, capsys, monkeypatch):
    def interrupted_build(self, *args, **kwargs):
        signal.raise_signal(signal.SIGTERM)

    monkeypatch.setattr(Scene, "build", interrupted_build)
    assert cli.main(["run", str(scene), "--out", str(tmp_path / "out"), "--no-progress"]) == 143
    assert "interrupted: 0 frames" in capsys.readouterr().err


def test_a_diverging_scene_exits_1_naming_the_step_and_a_stable_dt(scene, tmp_path, capsys):
    stiff = tmp_path / "stiff.toml"
    stiff.write_text(SCENE.replace("duration = 1.0", "duration = 1.0\nsubsteps = 1"))
    assert cli.main(["run", str(stiff), "--out", str(tmp_path / "o"), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "diverged at step" in err and "stable dt" in err


def test_info_prints_versions_arch_and_threads(capsys):
    assert cli.main(["info"]) == 0
    out = capsys.readouterr().out
    for word in ("ti_cloth", "taichi", "numpy", "arch", "threads"):
        assert word in out


def test_info_lists_the_extras_and_their_versions(capsys):
    from importlib.metadata import version

    assert cli.main(["info"]) == 0
    out = capsys.readouterr().out
    for extra, package in cli.EXTRAS.items():        # the test extra installs them all
        assert f"{extra:8} {package} {version(package)}" in out


def test_the_console_script_is_installed_and_quiet(scene, tmp_path):
    """The command prints its own output: no Taichi banner, no "Starting on arch" line
    (both back with --verbose)."""
    script = Path(sys.executable).with_name("ti-cloth")
    assert script.is_file(), "pip install the package to get the ti-cloth command"
    out = tmp_path / "cli"
    result = subprocess.run([str(script), "run", str(scene), "--out", str(out), "--frames", "2",
                             "--no-progress"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert len(frames_in(out)) == 2
    assert "[Taichi]" not in result.stdout + result.stderr
    env = {k: v for k, v in os.environ.items() if k != "ENABLE_TAICHI_HEADER_PRINT"}
    verbose = subprocess.run([str(script), "info", "--verbose"], capture_output=True, text=True,
                             timeout=300, env=env)
    assert "[Taichi] version" in verbose.stdout + verbose.stderr


def test_the_command_runs_from_a_source_tree_pip_never_installed(scene, tmp_path, monkeypatch,
                                                                  capsys):
    """The package on PYTHONPATH without its metadata (a machine without an index): the
    command still parses, runs a scene and says what it is."""
    import importlib.metadata as metadata

    real = metadata.version

    def version(name):
        if name == "ti_cloth":
            raise metadata.PackageNotFoundError(name)
        return real(name)

    monkeypatch.setattr(metadata, "version", version)
    assert cli.main(["run", str(scene), "--out", str(tmp_path / "o"), "--frames", "1",
                     "--no-progress"]) == 0
    assert len(frames_in(tmp_path / "o")) == 1
    with pytest.raises(SystemExit):
        cli.main(["--version"])
    assert "ti-cloth (not installed: run from a source tree)" in capsys.readouterr().out


def test_help_and_version_import_no_taichi():
    """--help and --version answer from the parser alone: Taichi is never imported (run in a
    fresh interpreter: this one has it)."""
    code = ("import sys\nfrom ti_cloth.app import cli\n"
            "for argv in (['--version'], ['--help'], ['run', '--help'], ['study', '--help']):\n"
            "    try:\n        cli.main(argv)\n    except SystemExit:\n        pass\n"
            "print('taichi imported' if 'taichi' in sys.modules else 'no taichi')\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=120)
    from importlib.metadata import version

    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().endswith("no taichi")
    assert f"ti-cloth {version('ti_cloth')}" in result.stdout
    assert "--mp4" in result.stdout and "--verbose" in result.stdout


def test_a_long_legal_run_is_announced_before_it_starts(tmp_path, capsys, monkeypatch):
    """400 x 400 particles at 2,000 steps per frame for a minute: the estimate (limits.Work)
    is days, printed before the run starts (the run itself is replaced here)."""
    from ti_cloth.app import runner

    long = tmp_path / "long.toml"
    long.write_text(SCENE.replace("rows = 5\ncols = 5", "rows = 400\ncols = 400")
                    .replace("duration = 1.0", "duration = 60\nsubsteps = 2000"))
    monkeypatch.setattr(runner, "run_scene", lambda scene, **kw: runner.RunResult(
        frames=[], outputs=[], steps=0, dt=scene.frame_dt, wall_seconds=0.0))
    assert cli.main(["run", str(long), "--out", str(tmp_path / "o"), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert re.search(r"note: 'tiny' is a long run: 3,600,000 steps, .* about [\d.]+ days", err)
    assert "finding its stable step" not in err      # 956,002 springs: not a large body


def test_a_large_body_is_announced_before_its_stable_step_is_sought(tmp_path, capsys, monkeypatch):
    """Above limits.LARGE_BODY springs the stable-step analysis takes seconds to a minute: the
    command says so first, naming the counts (lowered here below the 5 x 5 scene's 40 + 32 + 30 springs)."""
    from ti_cloth.app import scene as scene_module
    from ti_cloth.inputs import limits

    heard = []
    monkeypatch.setattr(limits, "LARGE_BODY", 101)
    original = scene_module.check_runnable
    monkeypatch.setattr(scene_module, "check_runnable",
                        lambda *args: (heard.append(capsys.readouterr().err), original(*args)))
    path = tmp_path / "tiny.toml"
    path.write_text(SCENE)
    assert cli.main(["run", str(path), "--out", str(tmp_path / "o"), "--no-progress",
                     "--frames", "1"]) == 0
    assert heard == ["note: 'tiny' has 25 particles and 102 springs: finding its stable step "
                     "takes a while\n"]

