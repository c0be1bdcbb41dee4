"""The camera and [output] tables of a scene file: where and how its frames are written."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..contact.colliders.shapes import Plane
from ..inputs import limits
from ..inputs.limits import EXPORT_FORMATS as FORMATS
from ..inputs.scene_file import Table
from ..render.camera import Camera
from ..render.renderer import SurfaceStyle

VIEWS = ("3d", "2d")


@dataclass
class Output:
    """Where and how frames are written."""

    folder: Path
    gif: bool = True
    mp4: bool = False
    width: int = 640
    height: int = 360
    supersample: int = 2
    gif_width: int = 480
    view: str = "3d"
    ground: float | None = None
    style: SurfaceStyle = field(default_factory=SurfaceStyle)
    export: tuple = ()          # geometry formats (export.FORMATS) written beside the frames
    checkpoint_every: int | None = None   # frames between saved states (None: runner decides)



def read_camera(table: Table):
    """(an explicit Camera, {}) when `position` is given, else (None, the Camera.fit options:
    direction, up, fov) to fit the body."""
    options = {}
    table.optional(options, "up", "vector")
    table.optional(options, "fov", within=limits.FOV)
    if table.has("position"):
        options["position"] = table.vector("position", unit="m", within=limits.COORDINATE)
        table.optional(options, "target", "vector", unit="m", within=limits.COORDINATE)
        camera = table.build(Camera, **options)
        table.finish()
        return camera, {}
    table.optional(options, "direction", "vector")
    table.finish()
    return None, options


def read_output(table: Table, name: str, colliders) -> Output:
    formats = table.value("formats", ["png", "gif"])
    if (not isinstance(formats, list) or not set(formats) <= {"png", "gif", "mp4", *FORMATS}
            or "png" not in formats):
        table.bad("formats", formats, 'a list of "png" (always) and any of "gif", "mp4", '
                   + ", ".join(f'"{f}"' for f in FORMATS))
    ground = table.value("ground", "auto")
    if ground == "auto":
        planes = [c for c in colliders if isinstance(c, Plane) and c.normal == (0.0, 1.0, 0.0)]
        ground = planes[0].point[1] if planes else None
    elif ground is False:
        ground = None
    elif (isinstance(ground, bool) or not isinstance(ground, (int, float))
          or not limits.COORDINATE.low <= ground <= limits.COORDINATE.high):
        table.bad("ground", ground, f'"auto", false or a height {limits.COORDINATE.text()}')
    options = {}
    table.optional(options, "style", lambda k: read_style(table.table(k)))
    for key, within in (("width", limits.IMAGE_SIDE), ("height", limits.IMAGE_SIDE),
                        ("supersample", limits.SUPERSAMPLE), ("gif_width", limits.IMAGE_SIDE)):
        table.optional(options, key, "integer", within=within)
    table.optional(options, "view", "string", choices=VIEWS)
    table.optional(options, "checkpoint_every", "integer", within=limits.FRAMES)
    folder = table.string("folder", f"renders/{name}")
    if not folder or "\0" in folder:
        table.bad("folder", folder, "a folder path")
    output = Output(folder=Path(folder), gif="gif" in formats, mp4="mp4" in formats,
                    ground=ground, export=tuple(f for f in FORMATS if f in formats), **options)
    samples = output.width * output.height * output.supersample**2
    if samples > limits.SAMPLES:
        table.bad("width", output.width, f"such that width x height x supersample^2 "
                   f"({output.width} x {output.height} x {output.supersample}^2) <= {limits.SAMPLES:_}")
    table.finish()
    return output


def read_style(table: Table) -> SurfaceStyle:
    options = {}
    for key in ("front", "back", "wire_colour", "particle_colour", "pin_colour"):
        if table.has(key):
            options[key] = table.vector(key)
    for key in ("checker", "strain_max", "wireframe", "particles", "line_width", "checker_contrast"):
        if table.has(key):
            options[key] = table.number(key, minimum=0.0)
    if table.has("strain"):
        options["strain"] = table.boolean("strain")
    style = table.build(SurfaceStyle, **options)
    table.finish()
    return style
