"""The `rbp` command line. Heavy modules are imported inside each command, so --help is instant.

A user's mistake (a bad scenario, a missing file) ends with one line on stderr naming the file,
the field and the reason, and exit status 2; never a traceback. Exit statuses: EXIT_STATUSES.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import json
import math
import os
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

from experiments.arguments import OneLineParser, decimal, input_file
from rb_drake.errors import (
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    RbpInputError,
    as_given,
    one_line,
    utf8_text,
)
from rbp.commands.common import RECEIVED as INTERRUPTS_RECEIVED
from rbp.commands.common import (
    UserError,
    check_dpi,
    check_output,
    check_seed,
    clean_interrupts,
    forget_outputs,
    load_scenario_spec,
    output_flag,
    plural,
    read_plan,
    refuse_empty_paths,
    restore_stdout,
)

if TYPE_CHECKING:
    from planning.plan_model import Plan

EXIT_STATUSES = """exit status:
  0  done (rbp plan: a plan was found and written; rbp check: the plan verifies, a partial
     plan as partial)
  1  ran but failed: no route or planning failed (rbp plan still writes the plan file, with
     success: false and the reason; with --partial, the climb to the stance nearest the
     goal), a plan that does not verify, a failed execution, a plan of no route given to
     simulate or rig-run (nothing to fly)
  2  bad input: one line on stderr, "error: FILE: FIELD: REASON" (never a traceback); also an
     output that cannot be written
  3  interrupted (Ctrl-C, SIGTERM, SIGHUP: one line on stderr; or the reader of the output
     closed it, as `| head` does): no output file is left half-written"""




def cmd_scenario_generate(args: argparse.Namespace) -> int:
    from rb_drake.files import atomic_write_text
    from rb_drake.generate import (
        MAX_ANCHOR_DENSITY,
        CaveConfig,
        density_problem,
        generate_cave,
        length_problem,
        values_problem,
    )
    from rb_drake.scenario import scenario_to_yaml

    lo, hi = args.length
    if (problem := length_problem(lo, hi)) is not None:
        raise UserError(f"--length: {problem}")
    if (problem := density_problem(args.anchor_density)) is not None:
        raise UserError(f"--anchor-density: {problem}")
    if (problem := values_problem(hi, args.anchor_density)) is not None:
        raise UserError(problem)  # up front: a 1000 m cave takes minutes to draw
    check_seed(args.seed)
    cfg = CaveConfig(anchor_density=args.anchor_density, length=(lo, hi))
    check_output(args.output)
    try:
        scn = generate_cave(args.kind, args.seed, cfg)
    except RuntimeError:  # no feasible start stance in any draw: name what to change
        found = (f"no {args.kind} cave with a feasible start stance after {cfg.max_redraws} "
                 f"draws from seed {args.seed}")
        if args.anchor_density < 1:  # below 0.5 a metre caves often have no start stance
            raise UserError(f"--anchor-density: {found} at {args.anchor_density:g} anchors "
                            f"per metre; give 1 to {MAX_ANCHOR_DENSITY:g} (default 3)") from None
        raise UserError(f"--seed: {found}; give another --seed or --length, or a denser "
                        "--anchor-density") from None
    command = (f"rbp scenario generate --kind {args.kind} --seed {args.seed} "
               f"--length {lo:g} {hi:g} --anchor-density {args.anchor_density:g}")
    atomic_write_text(args.output, f"# {command}\n{scenario_to_yaml(scn)}")
    print(one_line(f"wrote {args.output}: {scn.name}, {len(scn.anchors)} anchors, "
                   f"start stance {list(scn.start_stance)}"))
    return EXIT_OK


def cmd_scenario_import(args: argparse.Namespace) -> int:
    import re
    import shlex

    from rb_drake.files import atomic_write_text
    from rb_drake.scenario import scenario_to_yaml
    from rbp.api import import_scenario

    check_seed(args.seed)
    from rb_drake.terrain.import_cave import name_text_problem

    if args.name is not None and (problem := name_text_problem(args.name)) is not None:
        raise UserError(f"--name: {problem}")
    check_output(args.output, inputs={"the imported file": args.file})
    from rb_drake.errors import RbpInputError
    from rb_drake.terrain.polygon_files import declared_unit_of

    # a drawing read in the unit it declares: said on success, and on a refusal (a drawing in
    # metres that declares millimetres is a cave a thousand times too small)
    declared = declared_unit_of(args.file) if args.unit is None else None
    unit_note = (f"read in {declared}, the unit its $INSUNITS declares; --unit if it is not"
                 if declared is not None else "")
    try:
        scn = import_scenario(args.file, unit=args.unit, scale=args.scale,
                              simplify=args.simplify, anchor_density=args.anchor_density,
                              seed=args.seed, start=_pair(args.start), goal=_pair(args.goal),
                              name=args.name, plane_origin=_triple(args.plane_origin),
                              plane_normal=_triple(args.plane_normal),
                              resolution=args.resolution)
    except RbpInputError as e:
        if not unit_note or declared == "m":
            raise
        raise RbpInputError(f"{e.reason} ({unit_note})", file=e.file, field=e.field) from None
    words = ["rbp", "scenario", "import", args.file,
             *(["--unit", args.unit] if args.unit is not None else []),
             "--scale", f"{args.scale:g}", "--simplify", f"{args.simplify:g}",
             "--anchor-density", f"{args.anchor_density:g}", "--seed", str(args.seed)]
    for flag, value in (("--start", args.start), ("--goal", args.goal),
                        ("--plane-origin", args.plane_origin),
                        ("--plane-normal", args.plane_normal)):
        if value is not None:
            words += [flag, *(f"{v:g}" for v in value)]
    if args.resolution is not None:
        words += ["--resolution", f"{args.resolution:g}"]
    if args.name is not None:
        words += ["--name", args.name]
    # one line: a line break in a file name or --name would end the comment (YAML breaks
    # lines at NEL, LS and PS too)
    # and a file name that is not UTF-8 escaped (UnicodeEncodeError: a traceback)
    command = re.sub("[\n\r\x85\u2028\u2029]", " ", utf8_text(shlex.join(words)))
    atomic_write_text(args.output, f"# {command}\n{scenario_to_yaml(scn)}")
    print(one_line(f"wrote {args.output}: {scn.name}, {len(scn.walls)} rock polygons, "
                   f"{len(scn.anchors)} anchors, start {list(scn.start_pose)} in stance "
                   f"{list(scn.start_stance)}, goal {list(scn.goal_position)}"
                   + (f" ({unit_note})" if unit_note else "")))
    return EXIT_OK


def _pair(value: list[float] | None) -> tuple[float, float] | None:
    return None if value is None else (value[0], value[1])


def _triple(value: list[float] | None) -> tuple[float, float, float] | None:
    return None if value is None else (value[0], value[1], value[2])


def cmd_scenario_check(args: argparse.Namespace) -> int:
    import numpy as np

    from rb_drake.feasibility import check_poses

    scn = load_scenario_spec(args.scenario)
    check = check_poses(scn, scn.stance(scn.start_stance), np.array(scn.start_pose))
    alloc = check.allocation
    print(one_line(f"{scn.source}: ok: {scn.name}"))  # user text: escaped, as in errors
    print(f"  {len(scn.walls)} rock polygons, {len(scn.anchors)} anchors, gravity "
          f"{list(scn.gravity)} m/s^2")
    print(f"  start pose {list(scn.start_pose)} in stance {list(scn.start_stance)}: "
          f"P = {check.probability[0]:.5f} (p_min {scn.robot.p_min})")
    for i, aid in enumerate(scn.start_stance):
        print(f"    boom {i} -> {one_line(aid)}: tension {alloc.tensions[0, i]:6.2f} N, pull angle "
              f"{np.degrees(alloc.pull_angles[0, i]):+6.1f} deg, P = "
              f"{np.exp(alloc.log_probs[0, i]):.5f}")
    print(f"  goal {list(scn.goal_position)} +- {scn.goal_tolerance} m")
    return EXIT_OK


def cmd_scenario_show(args: argparse.Namespace) -> int:
    from rbp.api import draw

    check_dpi(args.dpi)
    check_output(args.output, picture=True, inputs={"the scenario's file": args.scenario})
    draw(load_scenario_spec(args.scenario, check_start=False), args.output, dpi=args.dpi)
    print(one_line(f"wrote {args.output}"))
    return EXIT_OK


def cmd_scenario_list(args: argparse.Namespace) -> int:
    from rb_drake.scenario import bundled_caves
    from systems.rig import RIG_SCENARIO

    for name, path in bundled_caves().items():
        print(f"{name:20s} {path}")
    print(f"{'rig':20s} {RIG_SCENARIO}  (the lab rig's frame: rbp plan rig, rbp rig-run)")
    return EXIT_OK


def _summary(plan: Plan, recorded: bool = False) -> str:
    search = plan.search.to_dict() if plan.search is not None else {}
    if not plan.success:
        hint = ""
        if search.get("stop") == "budget" and plan.planner == "rbp":  # not the naive's steps
            hint = ("; rbp plan --thorough searches on without a budget, --max-expansions N "
                    "or --time-limit S sets another")
        if plan.partial is not None and plan.p_path is not None:
            hint += (f"; partial plan: ends {plan.partial.goal_distance_m:.2f} m from the goal "
                     f"(p_path {plan.p_path:.4f}, regrasps {plan.regrasps})")
        return (f"success: false ({plan.reason}), time {plan.timing['total']:.2f} s"
                + hint)
    grasps = f" (grasps alone {plan.p_grasps:.4f})" if plan.p_grasps is not None else ""
    return (f"success: true, p_min {plan.p_min:.4f}, p_path {plan.p_path:.4f}{grasps}, "
            f"regrasps {plan.regrasps}, time {plan.timing['total']:.2f} s"
            + _route_quality(search, recorded, continuation=plan.start is not None))


def _route_quality(search: dict, recorded: bool = False,
                   continuation: bool = False) -> str:
    """How far the route is from the best one, as the anytime search proved it, and the
    refined lattice it was found on (planning.refinement). `recorded` (rbp check): said to be
    the search's record, which the verifier holds consistent but cannot prove without
    searching again (a lower bound copied onto the cost reads "optimal"). A `continuation`
    (a plan with `start`, systems.replanning) keeps the record of the plan it continues, whose
    route is not the continuation's (a retry adds a reach, a footstep replan climbs another
    route): said so."""
    text = _bound_text(search)
    refined = search.get("refined")
    if refined:
        step, angle = refined[-1]
        text += (f"; on the refined lattice {step * 100:g} cm / {angle:g} deg, the coarser "
                 "having no route")
    if recorded and text and continuation:
        text += (" (as the search record of the plan this continuation continues states it, "
                 "of that plan's route from the cave's start, not of this climb; not searched "
                 "again here)")
    elif recorded and text:
        text += " (as the plan's search record states it; not searched again here)"
    return text


def _bound_text(search: dict) -> str:
    if search.get("min_success") is not None:
        wanted = as_given(search["min_success"])
        return (f"; the fewest regrasps with predicted success >= {wanted} "
                f"(search cost {search['cost']:.4f}, exp(-cost) {math.exp(-search['cost']):.4f})")
    if search.get("quality") == "optimal":
        return f"; route optimal (search cost {search['cost']:.4f})"
    if search.get("bound") is not None:
        return (f"; route cost {search['cost']:.4f}, within {search['bound']:.2f}x of the "
                f"optimum (proven lower bound {search['lower_bound']:.4f}; first route "
                f"{search['first_cost']:.4f})")
    return ""


def _over_reading_limit(path: Path) -> str:
    """A note when a written plan is larger than rbp's readers accept (a long climb at a fine
    --dt), saying how to read it back; empty otherwise."""
    from rb_drake.input_files import max_input_bytes

    size, limit = path.stat().st_size, max_input_bytes()
    if size <= limit:
        return ""
    return (f" ({size / 2**20:.1f} MiB, over the {limit / 2**20:.1f} MiB reading limit: set "
            f"RBP_MAX_INPUT_MB={math.ceil(size / 2**20)} to check or simulate it)")


def cmd_plan(args: argparse.Namespace) -> int:
    from rbp.commands.plan import (
        SearchRecord,
        check_plan_output,
        plan_setup,
        provenance,
        read_plan_inputs,
        run_planner,
        write_pictures,
    )

    check_plan_output(args)
    if args.animate and args.no_pictures:  # it wrote no animation, silently
        raise UserError("--animate: draws the climb, which --no-pictures leaves out")
    if args.animate:
        from rbp.commands.plan import check_animation

        check_animation(args.animate, {"the scenario's file": args.scenario,
                                       "--from-plan's file": args.from_plan})
    if args.phase_figure is not None:  # what can be refused before planning
        if args.phase_figure < 0:
            raise UserError(f"--phase-figure: must be 0 or more, got {args.phase_figure}")
        if args.footsteps_only or args.no_pictures:
            flag = "--footsteps-only" if args.footsteps_only else "--no-pictures"
            raise UserError(f"--phase-figure: draws a phase's trajectory, which {flag} "
                            "leaves out")
    read_plan_inputs(args)  # before the planner's imports (170 MB): a refusal costs little
    scn, planner, cfg, motion = plan_setup(args)
    from planning.plan import write_plan

    partial = getattr(args, "partial", False)
    if partial and (planner != "rbp" or not motion):  # --from-plan's, once read
        flag = ("--planner naive" if args.planner == "naive" else "--from-plan's naive planner"
                if planner != "rbp" else "--footsteps-only" if args.footsteps_only
                else "--from-plan's footstep plan (made with --footsteps-only)")
        raise UserError(f"--partial: flies the partial climb through the whole pipeline of the "
                        f"rbp planner, which {flag} leaves out")
    record = SearchRecord()
    plan = run_planner(scn, planner, cfg, motion=motion, quiet=args.quiet, record=record,
                       partial=partial)
    plan = plan.replace(provenance=provenance(scn, planner, cfg, motion,
                                              getattr(args, "argv", None)))
    out = Path(args.output)
    from rb_drake.files import output_batch

    late = None
    with output_batch() as batch:  # the plan and its pictures, or (a full disk) none of them
        write_plan(plan, out)
        batch.say(lambda: f"wrote {out}{_over_reading_limit(out)}")
        if not args.no_pictures:
            late = write_pictures(scn, plan, out, args.phase_figure, args.animate,
                                  search=record.last, say=batch.say)
    if late is not None:  # a --phase-figure known only now: the plan and pictures are kept
        raise late
    _print_motion(plan)
    print(_summary(plan))
    return EXIT_OK if plan.success else EXIT_FAILED


def _print_motion(plan: Plan) -> None:
    from planning.pipeline import motion_summary

    rows = motion_summary(plan)
    if not rows:
        return
    room = [r for r in rows if r["room"]]
    inner = [r for r in rows if not r["seed_min_at_end"]]
    better_mean = sum(r["mean"] > r["seed_mean"] + 1e-9 for r in room)
    better_min = sum(r["min"] > r["seed_min"] + 1e-9 for r in inner)
    t = plan.timing
    phases = plural(len(rows), "phase")
    print(f"motion: {phases}; SCP raised the mean P on {better_mean} of the "
          f"{len(room)} with room (seed mean below 0.9999) and the minimum P on {better_min} of "
          f"the {len(inner)} whose seed's minimum is not at a fixed end; seeds "
          f"{t['seed_body'] + t['seed_reach']:.2f} s, SCP {t['scp_body'] + t['scp_reach']:.2f} s")


def _file_version(path: Path) -> tuple[int, ...] | None:
    """What changes when a file is written again or replaced (device, inode, size, time)."""
    try:
        info = os.stat(path)
    except OSError:
        return None
    return (info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns)


def cmd_check(args: argparse.Namespace) -> int:
    from planning.verify_between import resolution_text
    from rbp.progress import CheckProgress
    from systems.plan_check import plan_problems

    path = Path(args.plan)
    if args.stamp:  # before the verification: an unwritable folder was found after its ok line
        check_output(path, "--stamp", picture=None)
    read_as = _file_version(path)
    plan = read_plan(path)
    if plan.get("provenance") is not None:  # its configuration, as --from-plan reads it
        from rbp.commands.plan import check_recorded_config

        check_recorded_config(plan["provenance"]["config"], path)
    cave: list[str] = []
    if getattr(args, "scenario", None) is not None:  # rule scenario: the cave it is for
        from rbp.commands.common import cave_problems

        cave = cave_problems(plan, args.scenario)
    with CheckProgress(f"checking {path}", quiet=getattr(args, "quiet", False)) as bar:
        problems, departure = plan_problems(plan, str(path), progress=bar)
    problems = cave + problems
    for p in problems:  # the file's name escaped: a newline in it forged an `error:` line
        print(one_line(f"{path}: {p}"))
    if problems:
        print(one_line(f"{path}: {plural(len(problems), 'problem')}"))
        return EXIT_FAILED
    from planning.plan_model import Plan
    from planning.verify_climb import check_note

    model = Plan.from_dict(plan)
    n = sum(len(p.steps) for p in model.phases)
    between = ("and the motion between them, the straight line rbp rig-run commands and the "
               f"smooth path rbp simulate follows, {resolution_text()}"
               if model.time_step is not None
               else "not the motion between them (a footstep plan: end configurations only)")
    if departure is not None:
        between += (f" (rbp simulate's smooth path through the steps within {departure:.2f} "
                    f"of that resolution of the straight line)")
    note = check_note(model)
    if getattr(args, "scenario", None) is not None:
        note = "; ".join(filter(None, [f"made for the cave and robot of {args.scenario}", note]))
    print(one_line(f"{path}: ok: {plural(len(model.phases), 'phase')}, "
                   f"{plural(n, 'configuration')} verified, {between}; "
                   + (f"{note}; " if note else "") + _summary(model, recorded=True)))
    if args.stamp:
        from planning.plan import write_plan
        from planning.plan_file import stamp

        if _file_version(path) != read_as:  # another command wrote it during the check: the
            # stamp replaced that new plan with this old one, stamped as verified
            raise UserError(f"{path}: --stamp: the file changed while it was being checked "
                            "(another command wrote it); not stamped: check it again")
        write_plan(stamp(plan), path)
        print(one_line(f"{path}: stamped as verified"))
    return EXIT_OK


def cmd_demo(args: argparse.Namespace) -> int:
    """The main job on the bundled demo cave: check it, picture it, report the start stance."""
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UserError(f"{out}: --out: is a file; give a folder (its outputs are written "
                        "into it)")
    for name in ("cave.png", "start.json", "plan.json"):  # checked before any work
        check_output(out / name, "--out", picture=name.endswith(".png"),
                     inputs={"the scenario's file": args.scenario})
    scn = load_scenario_spec(args.scenario)  # before the heavy imports: a refusal costs little
    import numpy as np

    from rb_drake.draw import scenario_figure
    from rb_drake.feasibility import check_poses
    from rb_drake.files import atomic_save_figure, atomic_write_text, output_batch

    stance = scn.stance(scn.start_stance)
    check = check_poses(scn, stance, np.array(scn.start_pose))
    alloc = check.allocation
    report = {
        "scenario": scn.to_dict(resolved=True),
        "start": {
            "pose": list(scn.start_pose),
            "stance": list(scn.start_stance),
            "tension": [float(f) for f in alloc.tensions[0]],
            "pull_angle_deg": [float(np.degrees(a)) for a in alloc.pull_angles[0]],
            "p_grasp": [float(np.exp(v)) for v in alloc.log_probs[0]],
            "p_success": float(check.probability[0]),
        },
    }
    with output_batch() as batch:  # the cave's picture and report, or neither
        picture = atomic_save_figure(scenario_figure(scn), out / "cave.png", dpi=120)
        data = atomic_write_text(out / "start.json", json.dumps(report, indent=1))
        batch.say(f"{scn.name}: start stance P = {check.probability[0]:.5f}; "
                  f"wrote {picture} and {data}")
    if args.plan:
        from planning.footsteps import FootstepConfig
        from planning.pipeline import PipelineConfig
        from planning.plan import write_plan
        from rbp.commands.plan import provenance, run_planner, write_pictures

        cfg = PipelineConfig(footstep=FootstepConfig(seed=0, max_expansions=400))
        plan = run_planner(scn, "rbp", cfg)
        plan = plan.replace(provenance=provenance(scn, "rbp", cfg, True,
                                                  getattr(args, "argv", None)))
        from planning.pipeline import motion_summary

        # Fig. 6 for the phase where SCP gained most
        rows = motion_summary(plan)
        best = max(rows, key=lambda r: r["mean"] - r["seed_mean"])["phase"] if rows else None
        with output_batch() as batch:  # the plan and its pictures, or none of them
            write_plan(plan, out / "plan.json")
            batch.say(f"wrote {out / 'plan.json'}")
            write_pictures(scn, plan, out / "plan.json", best, None, say=batch.say)
        _print_motion(plan)
        print(_summary(plan))
        if not plan.success:
            return EXIT_FAILED
    return EXIT_OK


def build_parser() -> argparse.ArgumentParser:
    # its usage errors in one line (`error: ... (see rbp plan --help)`); the subcommands'
    # parsers are of its class too (add_subparsers makes its parent's class)
    parser = OneLineParser(prog="rbp", description=__doc__.split("\n\n")[0],
                                     epilog=EXIT_STATUSES,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)

    demo = sub.add_parser("demo", help="run the main job on the bundled demo cave")
    demo.add_argument("--scenario", default="demo-shaft", type=input_file,
                      help="scenario file or bundled cave name (default: demo-shaft)")
    demo.add_argument("--out", default="out/demo", help="output folder (default: out/demo)")
    demo.add_argument("--no-plan", dest="plan", action="store_false",
                      help="only check and draw the cave (skip the footstep plan)")
    demo.set_defaults(func=cmd_demo)

    plan = sub.add_parser("plan", help="plan a climb and write a plan file and its picture",
                          epilog=EXIT_STATUSES,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    plan.add_argument("scenario", nargs="?", type=input_file,
                      help="scenario file or bundled cave name (not with --from-plan)")
    plan.add_argument("-o", "--output", required=True, help="plan file to write (.json)")
    plan.add_argument("--planner", choices=("rbp", "naive"), help="default rbp")
    plan.add_argument("--config", metavar="FILE", type=input_file,
                      help="planner configuration (YAML: footstep, seed, scp, dt, optimise, "
                           "motion_retries; see docs/formats.md); flags given override it")
    plan.add_argument("--from-plan", metavar="PLAN", type=input_file,
                      help="repeat the plan PLAN was made with: its scenario, planner, "
                           "configuration and seed (flags given override them)")
    plan.add_argument("--seed", type=int,
                      help="seed of the planner's sampling, 0 or more (default 0)")
    plan.add_argument("--max-expansions", type=int,
                      help="give up after expanding this many stances (default 1000, or 300 "
                           "per metre from the start to the goal if more)")
    plan.add_argument("--search", choices=("complete", "hybrid", "sampled"),
                      help="footstep search: complete (default; on the 2 cm x 2.5 deg pose "
                           "lattice: finds a route whenever one passes through its points, "
                           "and where none does, searches the 1 cm x 1.25 deg lattice too "
                           "(footstep.refine)), sampled (the search before the complete one) or "
                           "hybrid (sampling for 150 expansions, then the complete search)")
    plan.add_argument("--thorough", action="store_true",
                      help="the oracle: the complete search without an expansion budget, on "
                           "to the optimal route (the lowest search cost, proved) or a proof "
                           "that none passes through the lattices' points; with --time-limit, "
                           "the best route found and how far from the optimum it is proved "
                           "to be")
    plan.add_argument("--min-success", type=decimal, metavar="P",
                      help="the route with the fewest regrasps whose predicted success (the "
                           "search's, exp(-cost)) is at least P, or the proof that none "
                           "reaches P (complete search, no expansion budget unless given)")
    plan.add_argument("--repair", action="store_true",
                      help="then improve the route window by window, each window searched to "
                           "its optimum (planning.route_repair): routes nearer the most robust "
                           "at about three times the footstep time (docs/benchmarks.md)")
    plan.add_argument("--partial", action="store_true",
                      help="when no route reaches the goal, climb to the expanded stance "
                           "nearest it (the plan still says success: false, exit status 1)")
    plan.add_argument("--time-limit", type=decimal, metavar="SECONDS",
                      help="give up after this many seconds of footstep search (default none)")
    plan.add_argument("--dt", type=decimal,
                      help="seconds between trajectory steps, 0.25 to 60 (default 0.5; steps "
                           "are 5 cm apart)")
    plan.add_argument("--no-scp", action="store_true",
                      help="keep the seed trajectories (no sequential convex programming)")
    plan.add_argument("--footsteps-only", action="store_true",
                      help="stop after the footstep plan (phases hold only transition poses)")
    plan.add_argument("--no-pictures", action="store_true",
                      help="write the plan file only (no PLAN.png, no search picture)")
    plan.add_argument("-q", "--quiet", action="store_true",
                      help="no progress line (it is shown only when stderr is a terminal)")
    plan.add_argument("--phase-figure", type=int, metavar="K",
                      help="also draw phase K's tensions and probability, seed against SCP "
                           "(the paper's Fig. 6), beside the plan")
    plan.add_argument("--animate", metavar="FILE",
                      help="also write an animation of the climb (.gif, or .mp4 with ffmpeg)")
    plan.set_defaults(func=cmd_plan)

    check = sub.add_parser("check", help="re-verify a plan file from scratch")
    check.add_argument("plan", type=input_file)
    check.add_argument("--stamp", action="store_true",
                       help="when the plan verifies, write into it a stamp (a hash of its "
                            "content) so simulate and rig-run need not verify it again")
    check.add_argument("-q", "--quiet", action="store_true",
                       help="no progress line (shown only when stderr is a terminal and the "
                            "check takes over a second)")
    check.add_argument("--scenario", metavar="CAVE", type=input_file,
                       help="a scenario file or a bundled cave's name: the plan must also "
                            "have been made for this cave and robot (the plan is verified "
                            "against the cave and robot it embeds, which an edit can change)")
    check.set_defaults(func=cmd_check)

    scn = sub.add_parser("scenario", help="generate, import, check and show caves")
    ssub = scn.add_subparsers(dest="scenario_command", required=True)
    gen = ssub.add_parser("generate", help="a seeded random cave")
    gen.add_argument("--kind", choices=("shaft", "crevasse", "rockfall"), default="shaft",
                     help="a vertical shaft to climb, or a horizontal passage with a crevasse "
                          "or a rockfall to cross (default shaft)")
    gen.add_argument("--seed", type=int, default=0,
                     help="random seed, 0 or more: the same seed gives the same cave (default 0)")
    gen.add_argument("--anchor-density", type=decimal, default=3.0,
                     help="anchors per metre of rock surface, above 0 and at most "
                          "20 (default 3.0)")
    gen.add_argument("--length", type=decimal, nargs=2, default=(7.0, 9.0), metavar=("MIN", "MAX"),
                     help="shaft height or passage length, drawn in this range in m (default "
                          "7 9; the experiments use 4.5 5)")
    gen.add_argument("-o", "--output", required=True, help="scenario file to write (.yaml)")
    gen.set_defaults(func=cmd_scenario_generate)
    imp = ssub.add_parser(
        "import", help="a cave from a file of rock: a polygon drawing (GeoJSON, DXF, SVG) or "
                       "a mesh or point cloud cut by a plane (STL, OBJ, PLY); needs the extra "
                       "rbp[import]")
    imp.add_argument("file", type=input_file,
                     help="the rock: a 2D section of closed outlines (.geojson/.json, .dxf, "
                          ".svg; x to the side, y up), or a 3D scan cut by a plane (.stl/.obj/"
                          ".ply mesh, .ply point cloud; z up)")
    imp.add_argument("-o", "--output", required=True, help="scenario file to write (.yaml)")
    imp.add_argument("--unit", choices=("m", "cm", "mm", "in", "ft"), default=None,
                     help="the unit of the file's coordinates (default: the unit a DXF "
                          "declares in $INSUNITS, else m)")
    imp.add_argument("--scale", type=decimal, default=1.0,
                     help="a factor on the coordinates besides the unit (default 1)")
    imp.add_argument("--simplify", type=decimal, default=0.0, metavar="TOL",
                     help="simplify outlines to TOL metres (default 0: as drawn; a scan's "
                          "section: 0.01)")
    imp.add_argument("--anchor-density", type=decimal, default=3.0,
                     help="anchors per metre of rock surface, above 0 and at most 20 "
                          "(default 3.0)")
    imp.add_argument("--seed", type=int, default=0,
                     help="seed of the anchors, 0 or more: the same seed, the same cave "
                          "(default 0)")
    imp.add_argument("--start", type=decimal, nargs=2, metavar=("X", "Y"),
                     help="the body's start position in m, in the section's frame (default: "
                          "the lowest free position with a feasible stance, 1.5 m above the "
                          "bottom if one there has)")
    imp.add_argument("--goal", type=decimal, nargs=2, metavar=("X", "Y"),
                     help="the goal in m, in the section's frame (default: the highest free "
                          "position reached from the start with an anchor in reach of each "
                          "boom, the upper booms' 0.5 m above it)")
    imp.add_argument("--name", help="the scenario's name (default: the file's name)")
    imp.add_argument("--plane-origin", type=decimal, nargs=3, metavar=("X", "Y", "Z"),
                     help="scans: a point of the cutting plane, in the scan's coordinates, "
                          "and the section's 2D origin (default: the scan's bounding-box "
                          "centre)")
    imp.add_argument("--plane-normal", type=decimal, nargs=3, metavar=("X", "Y", "Z"),
                     help="scans: the cutting plane's normal (default 1 0 0: a vertical "
                          "plane; the section's x is world y, its y world z, up)")
    imp.add_argument("--resolution", type=decimal, metavar="R",
                     help="point clouds: outline the points within R metres of the plane, "
                          "bridging gaps up to 2R (default: about 4 point spacings, from the "
                          "cloud's density); a mesh's section is exact")
    imp.set_defaults(func=cmd_scenario_import)
    chk = ssub.add_parser("check", help="validate a scenario and summarise it")
    chk.add_argument("scenario", type=input_file)
    chk.set_defaults(func=cmd_scenario_check)
    show = ssub.add_parser("show", help="draw a scenario with the robot in its start stance")
    show.add_argument("scenario", type=input_file)
    show.add_argument("-o", "--output", required=True, help="picture to write (.png, .pdf, .svg)")
    show.add_argument("--dpi", type=int, default=120,
                      help="the picture's resolution, 20 to 600 dots per inch (default 120)")
    show.set_defaults(func=cmd_scenario_show)
    lst = ssub.add_parser("list", help="the bundled caves")
    lst.set_defaults(func=cmd_scenario_list)
    from experiments.cli import add_experiment_command
    from rbp.commands.rig import add_rig_commands
    from rbp.commands.simulate import add_simulate_command

    add_simulate_command(sub)
    add_rig_commands(sub)
    # rbp bench forwards its arguments, so that its heavy module loads only when it runs.
    bench = sub.add_parser("bench", add_help=False,
                           help="benchmark against cvxpy, SLSQP, IPOPT and the naive planner "
                                "(rbp bench --help)")
    bench.add_argument("args", nargs=argparse.REMAINDER)
    bench.set_defaults(func=cmd_bench)
    add_experiment_command(sub)
    return parser


def cmd_bench(args: argparse.Namespace) -> int:
    from experiments.bench import main as bench_main

    return bench_main(args.args, prog="rbp bench")


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns its exit status (EXIT_STATUSES)."""
    from rb_drake.environment import standard_streams

    standard_streams()  # a closed stdout or stderr, an ASCII-only one
    try:
        with clean_interrupts():  # Ctrl-C, SIGTERM, SIGHUP unwind: no temporary file left
            return _main(argv)
    except KeyboardInterrupt:
        # Outputs are written to a temporary file and renamed, so nothing is left half-written.
        with contextlib.suppress(OSError, ValueError):  # a hung-up terminal (SIGHUP): EIO
            print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # The reader of our output stopped reading (`rbp plan ... | head -1`): stop as if
        # interrupted, quietly, with what is still buffered sent nowhere.
        with contextlib.suppress(OSError, ValueError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_INTERRUPTED
    except Exception as e:
        # Ctrl-C while compiled (numba) code calls back into Python arrives wrapped in a
        # SystemError, and a library may turn it into another error: after an interrupt,
        # whatever ends the command is the interrupt.
        if not (INTERRUPTS_RECEIVED or _caused_by_interrupt(e)):
            raise
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    finally:
        restore_stdout()  # the messages of a command that wrote to standard output


def _caused_by_interrupt(error: BaseException | None) -> bool:
    seen = 0
    while error is not None and seen < 10:
        if isinstance(error, KeyboardInterrupt):
            return True
        error, seen = error.__cause__ or error.__context__, seen + 1
    return False


def _main(argv: list[str] | None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    from rb_drake.environment import (
        library_settings,
        quiet_matplotlib,
        threads_adapt_setting,
        threads_setting,
    )
    from rb_drake.input_files import max_input_bytes, max_input_values

    try:  # the environment, before numba, matplotlib or Drake is imported
        threads_setting()  # a malformed RBP_THREADS is refused before any work
        threads_adapt_setting()
        library_settings()  # and numba's and OpenMP's variables
        max_input_bytes()  # and so are the reading limits' (they fell back to the default)
        max_input_values()
    except RbpInputError as e:
        print(f"error: {one_line(str(e))}", file=sys.stderr)
        return EXIT_USAGE
    quiet_matplotlib()
    if argv[:1] == ["bench"]:  # all its options belong to experiments.bench (--help included)
        return cmd_bench(argparse.Namespace(args=argv[1:]))
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = argv  # the command line, for the plan's provenance
    from planning.config_io import ConfigError
    from rb_drake.scenario import ScenarioError

    try:
        forget_outputs()
        refuse_empty_paths(parser, args)
        return int(args.func(args) or 0)
    except (ScenarioError, ConfigError, RbpInputError) as e:  # UserError among them
        print(f"error: {one_line(str(e))}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:
        raise  # the reader went away (`main` handles it), not a file of the user's
    except OSError as e:  # an output that cannot be written, an input that cannot be read
        flag = output_flag(e.filename)  # `-o`, `--json`, ...: which option's file failed
        where = f"{e.filename or '(output)'}: {flag}" if flag else (e.filename or "(file)")
        # an OSError made from a message alone (matplotlib's, tempfile's) has no strerror
        print(one_line(f"error: {where}: {e.strerror or e}"), file=sys.stderr)
        return EXIT_USAGE


def entry() -> NoReturn:
    """The `rbp` executable (and `python -m rbp`): `main`, then exit without tearing the
    interpreter down. Teardown garbage-collects every module's objects (numba's typing tables,
    Drake, networkx graphs), 0.3 s of a 2.5 s `rbp plan`, and there is nothing left for it to
    do: outputs are written to a temporary file and renamed, exit handlers still run, and the
    output streams are flushed. With a non-daemon thread still running, the usual exit waits for
    it. Tests call `main`, which returns."""
    status = main()
    if any(t.is_alive() and not t.daemon and t is not threading.main_thread()
           for t in threading.enumerate()):
        sys.exit(status)
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        # A closed pipe (`rbp ... | head`) or a closed stream has nothing left to flush.
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    os._exit(status)


if __name__ == "__main__":
    entry()
