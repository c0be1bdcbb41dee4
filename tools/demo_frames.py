"""Check that every demo writes bit-identical frames before and after a change.

    python tools/demo_frames.py record hashes.json     # before: sha256 of every frame of every demo
    python tools/demo_frames.py check hashes.json      # after: the same run, compared; exit 1 on a change

Each demo runs in its own process (`demos/<name>.py --frames N --no-progress --out-dir ...`) at
its full image size, so the frames depend on the simulation, the renderer and the scene reader.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

DEMOS = Path(__file__).resolve().parent.parent / "demos"


def frame_hashes(frames: int, arch: str) -> dict[str, list[str]]:
    """{demo name: [sha256 of frame_00000.png, ...]} of every demo script."""
    hashes = {}
    for script in sorted(DEMOS.glob("*.py")):
        with tempfile.TemporaryDirectory() as out:
            subprocess.run([sys.executable, str(script), "--frames", str(frames), "--no-progress",
                            "--arch", arch, "--out-dir", out], check=True, stdout=subprocess.DEVNULL)
            pngs = sorted(Path(out).glob("frame_*.png"))
            hashes[script.stem] = [hashlib.sha256(p.read_bytes()).hexdigest() for p in pngs]
        print(f"{script.stem}: {len(hashes[script.stem])} frames", flush=True)
    return hashes


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mode", choices=["record", "check"])
    parser.add_argument("file", type=Path, help="JSON of frame hashes")
    parser.add_argument("--frames", type=int, default=12, help="frames per demo (default 12)")
    parser.add_argument("--arch", default="cpu")
    args = parser.parse_args(argv)
    hashes = frame_hashes(args.frames, args.arch)
    if args.mode == "record":
        args.file.write_text(json.dumps(hashes, indent=1))
        return 0
    expected = json.loads(args.file.read_text())
    changed = [name for name in sorted(set(expected) | set(hashes))
               if expected.get(name) != hashes.get(name)]
    for name in changed:
        old, new = expected.get(name, []), hashes.get(name, [])
        first = next((k for k, (a, b) in enumerate(zip(old, new)) if a != b), min(len(old), len(new)))
        print(f"CHANGED {name}: first differing frame {first} ({len(old)} before, {len(new)} after)")
    print(f"{len(hashes) - len(changed)} of {len(hashes)} demos bit-identical")
    return 1 if changed else 0


if __name__ == "__main__":
    raise SystemExit(main())
