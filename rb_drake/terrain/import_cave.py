"""`rbp scenario import`: a cave from a file of rock, a polygon drawing (GeoJSON, DXF, SVG:
`polygon_files`) or a mesh or point cloud cut by a plane (STL, OBJ, PLY: `mesh_section`)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import TYPE_CHECKING

from rb_drake.errors import RbpInputError, utf8_text
from rb_drake.scenario import MAX_NAME
from rb_drake.terrain.polygon_files import MESH_SUFFIXES, UNITS, missing_extra, read_rock

if TYPE_CHECKING:
    from shapely.geometry import Polygon

    from rb_drake.scenario import Scenario

MESH_SIMPLIFY = 0.01      # m: a mesh section's outline simplified this far unless --simplify says


@dataclasses.dataclass(frozen=True)
class ImportOptions:
    """How a file of rock becomes a cave (`rbp scenario import`'s options)."""

    unit: str | None = None          # the file's unit: m, cm, mm, in or ft (None: the unit
    #                                  a DXF declares, else m)
    scale: float = 1.0               # and a factor on top of it (a drawing's scale)
    simplify: float = 0.0            # m: outlines simplified to this tolerance (0: as drawn)
    anchor_density: float = 3.0      # anchors per metre of rock surface
    seed: int = 0                    # anchors drawn from this seed: the same seed, the same cave
    start: tuple[float, float] | None = None  # m: where the body hangs at the start
    goal: tuple[float, float] | None = None   # m: the goal; both chosen when None
    name: str | None = None          # the scenario's name (default: the file's stem)
    plane_origin: tuple[float, float, float] | None = None  # meshes: the cutting plane
    plane_normal: tuple[float, float, float] | None = None
    resolution: float | None = None  # m, point clouds only: the slab and the outline's gaps
    #                                  (None: from the cloud's density, mesh_section's)


def import_cave(path: str | Path, options: ImportOptions | None = None) -> Scenario:
    """The cave of the rock in `path` (see ImportOptions); raises RbpInputError naming the file
    and the problem for anything that is not closed, simple rock or makes no climbable cave."""
    from rb_drake.generate import CaveConfig
    from rb_drake.terrain.cave_from_rock import scenario_from_rock

    opts = options or ImportOptions()
    path = Path(path)
    _check(opts)
    try:
        import shapely  # noqa: F401  (every reader and the cave's assembly need it)
    except ImportError:
        raise missing_extra("shapely") from None
    scan = path.suffix.lower() in MESH_SUFFIXES
    if scan:
        rock = _mesh_rock(path, opts)
    else:
        if opts.plane_origin is not None or opts.plane_normal is not None:
            raise RbpInputError("only for a mesh or point cloud (.stl, .obj, .ply)",
                                file=str(path), field="--plane-origin/--plane-normal")
        if opts.resolution is not None:  # a point cloud's: a drawing's import ignored it
            raise RbpInputError("only for a point cloud (.ply, .obj): a drawing's outlines are "
                                "read as drawn", file=str(path), field="--resolution")
        rock = read_rock(path, opts.unit, opts.scale, opts.simplify)
    from rb_drake.input_files import max_input_values

    cfg = CaveConfig(anchor_density=opts.anchor_density)
    # the default name, the file's: its bytes that are not UTF-8 escaped, so that it reads back
    scn = scenario_from_rock(rock, seed=opts.seed, config=cfg, start=opts.start,
                             goal=opts.goal, name=opts.name or utf8_text(path.stem)[:MAX_NAME],
                             source=str(path),
                             framed=scan,  # a scan's rock is a frame minus the free space
                             max_values=max_input_values())
    _check_readable(path, scn)
    return scn


def name_text_problem(name: str) -> str | None:
    """Why `name` cannot be a scenario's name, or None: a lone surrogate (bytes of a command
    line that are not UTF-8) could not be written as UTF-8 (a traceback), nor read back."""
    if utf8_text(name) == name:
        return None
    return (f"not UTF-8 text ({utf8_text(name)[:80]}: bytes that are not UTF-8, or a lone "
            "surrogate); give a name in UTF-8")


def _check_readable(path: Path, scn: Scenario) -> None:
    """Refuse a cave whose file rbp could not read back: over the limit on a YAML document's
    values (3 a vertex of 50,000 outline vertices, 23 an anchor, may exceed it)."""
    from rb_drake.input_files import count_values, max_input_values
    from rb_drake.terrain.cave_from_rock import too_many_values

    values, limit = count_values(scn.to_dict()), max_input_values()
    if values > limit:
        raise too_many_values(str(path), f"{values:,}", limit)


def _check(opts: ImportOptions) -> None:
    from rb_drake.generate import density_problem  # the generator's range; it loads the kernel

    if opts.unit is not None and opts.unit not in UNITS:
        raise RbpInputError(f"must be one of {sorted(UNITS)}, got {opts.unit!r}", field="--unit")
    if (problem := density_problem(opts.anchor_density)) is not None:
        raise RbpInputError(problem, field="--anchor-density")
    if opts.resolution is not None and not (math.isfinite(opts.resolution)
                                            and opts.resolution > 0):
        raise RbpInputError(f"must be a positive number of metres, got {opts.resolution:g}",
                            field="--resolution")
    for flag, point in (("--start", opts.start), ("--goal", opts.goal),
                        ("--plane-origin", opts.plane_origin),
                        ("--plane-normal", opts.plane_normal)):
        if point is not None and not all(math.isfinite(v) and abs(v) <= 1e4 for v in point):
            raise RbpInputError(f"must be finite numbers of at most 1e4 in magnitude, got "
                                f"{list(point)}", field=flag)
    if opts.plane_normal is not None and not any(opts.plane_normal):
        raise RbpInputError("the zero vector has no direction", field="--plane-normal")


def _mesh_rock(path: Path, opts: ImportOptions) -> list[Polygon]:
    """The section of a mesh or point cloud, in metres. The mesh is read in its own unit:
    resolution and tolerance go to it in that unit, and its section comes back scaled."""
    try:
        from rb_drake.terrain.mesh_section import section_polygons
    except ModuleNotFoundError as e:
        if e.name == "rb_drake.terrain.mesh_section":
            raise RbpInputError("mesh import needs rb_drake.terrain.mesh_section",
                                file=str(path)) from None
        raise missing_extra(e.name or "trimesh") from None
    from shapely.affinity import scale as scaled

    factor = UNITS[opts.unit or "m"] * opts.scale
    if not (math.isfinite(opts.scale) and opts.scale > 0):
        raise RbpInputError(f"must be a positive number, got {opts.scale:g}", field="--scale")
    if not (math.isfinite(opts.simplify) and opts.simplify >= 0):
        raise RbpInputError(f"must be 0 or more metres, got {opts.simplify:g}",
                            field="--simplify")
    # a scan's facets are far finer than the planner's 2 cm lattice: without a tolerance of
    # its own, a section is simplified to MESH_SIMPLIFY (0 would keep every facet's vertex)
    simplify = opts.simplify if opts.simplify > 0 else MESH_SIMPLIFY
    section = section_polygons(path, opts.plane_origin, opts.plane_normal,
                               None if opts.resolution is None else opts.resolution / factor,
                               simplify / factor, metres_per_unit=factor)
    return [scaled(p, factor, factor, origin=(0.0, 0.0)) for p in section]
