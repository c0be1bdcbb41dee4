"""Every code block of README.md and docs/ runs as written, in order: the Python blocks of a
page in one fresh process (from a folder holding the repository's demos/), the TOML blocks
read by the scene reader, and every command of a shell block names files that exist and, for
`ti-cloth`, arguments the command accepts. (`text` blocks are usage synopses and output.)"""

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from ti_cloth.app.cli import build_parser
from ti_cloth.app.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.M | re.S)
KNOWN = {"python", "toml", "bash", "text", ""}


def blocks(page: Path, language: str) -> list[str]:
    return [body for lang, body in FENCE.findall(page.read_text()) if lang == language]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_block_says_its_language(page):
    languages = {lang for lang, _ in FENCE.findall(page.read_text())}
    assert languages <= KNOWN, f"{page.name}: blocks in {sorted(languages - KNOWN)}"


@pytest.mark.parametrize("page", [p for p in PAGES if blocks(p, "python")], ids=lambda p: p.name)
def test_the_python_blocks_run_in_order(page, tmp_path):
    (tmp_path / "demos").symlink_to(ROOT / "demos")
    script = "\n".join(blocks(page, "python"))
    done = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, f"{page.name}'s code blocks, run in order:\n{done.stderr[-3000:]}"


def toml_blocks():
    return [(page, body) for page in PAGES for body in blocks(page, "toml")]


@pytest.mark.parametrize("page, body", toml_blocks(), ids=lambda v: getattr(v, "name", ""))
def test_the_toml_blocks_are_scenes_or_parts_of_one(page, body, tmp_path):
    """A whole scene loads; a part (tables of settings) loads in place of those tables of
    demos/study_cloth.toml."""
    tables = set(re.findall(r"^\[(\w+)\]", body, re.M))
    if "bodies" not in body:
        study = (ROOT / "demos" / "study_cloth.toml").read_text()
        kept = [section for section in re.split(r"^(?=\[)", study, flags=re.M)
                if not any(section.startswith(f"[{table}]") for table in tables)]
        body = "".join(kept) + "\n" + body
    (tmp_path / "assets").symlink_to(ROOT / "demos" / "assets")
    path = tmp_path / "scene.toml"
    path.write_text(body)
    load_scene(path)


def commands():
    found = []
    for page in PAGES:
        for body in blocks(page, "bash"):
            for line in body.splitlines():
                line = line.split(" #")[0].strip()
                if line and not line.startswith("#"):
                    found.extend((page, part.strip()) for part in line.split("&&"))
    return found


@pytest.mark.parametrize("page, command", commands(), ids=lambda v: getattr(v, "name", v))
def test_the_shell_commands_name_real_files_and_arguments(page, command):
    words = shlex.split(command)
    for word in words:
        if word.endswith((".py", ".toml")) and not word.startswith("-"):
            assert (ROOT / word).exists(), f"{page.name}: {command!r} names {word}, not a file"
    if words[0] == "ti-cloth":
        build_parser().parse_args(words[1:])        # SystemExit(2) on an unknown argument
