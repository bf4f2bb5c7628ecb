"""`rbp rig-run`, `rbp rig-replay` and `rbp rig-report`: a plan's body phase on the rig.

Heavy modules are imported inside the handlers, so `rbp --help` stays instant. A user's mistake
raises `rbp.commands.common.UserError` with one line: the file, the field and the reason.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from experiments.arguments import decimal, input_file
from rb_drake.errors import EXIT_FAILED, EXIT_OK, one_line

MIN_PERIOD, MAX_PERIOD = 0.01, 1.0  # s between rig commands: 100 a second to one a second


def check_lcm_url(url: str) -> None:
    """`--lcm-url` checked whole and opened once, before the plan is verified (garbage://
    failed after 9 s with LCM's own "Error: ..." line; udpm://999.1.1.1:99999 printed one and
    ran on without a bus)."""
    from rbp.commands.common import UserError
    from systems.lcm_url import lcm_url_problem, open_problem

    # an empty URL is LCM's default, $LCM_DEFAULT_URL: only opening it tells
    problem = (lcm_url_problem(url) if url else None) or open_problem(url)
    if problem:
        raise UserError(f"--lcm-url: {url!r} {problem}" if problem.startswith("is not")
                        else f"--lcm-url: {url!r}: {problem}")


def add_rig_commands(subparsers) -> None:
    """Declare the three rig subcommands on `rbp`'s subparsers."""
    run = subparsers.add_parser("rig-run", help="run a body phase of a plan on the rig over LCM")
    run.add_argument("plan", type=input_file, help="plan file (reachbot-plan/1, .json)")
    run.add_argument("--phase", type=int, default=0,
                     help="index of the body phase to run (default 0)")
    run.add_argument("--lcm-url", default="memq://",
                     help="LCM bus of the rig (default memq://, in-process; the hardware "
                          "needs its udpm:// URL)")
    run.add_argument("--sim-rig", action="store_true",
                     help="answer with the simulated rig, in this process on memq://")
    run.add_argument("--seed", type=int, default=0, help="seed of the simulated rig's noise")
    run.add_argument("--period", type=decimal, default=0.1,
                     help="seconds between commands, 0.01 to 1 (default 0.1)")
    run.add_argument("--log", default="rig.lcm",
                     help="LCM log of every message (default rig.lcm)")
    run.add_argument("--scenario", metavar="CAVE", type=input_file,
                     help="a scenario file or a bundled cave's name: refuse the plan unless it "
                          "was made for this cave and robot (the rig's boom length and tension "
                          "clamps are the plan's robot's)")
    run.add_argument("--no-verify", dest="verify", action="store_false",
                     help="run the plan without verifying it first (experiments only; warns "
                          "on stderr; the rig's own limit and rate guards stay on)")
    run.set_defaults(func=cmd_rig_run)

    replay = subparsers.add_parser("rig-replay",
                                   help="replay a rig log through the grasp monitor")
    replay.add_argument("log", type=input_file, help="LCM log written by rbp rig-run")
    replay.set_defaults(func=cmd_rig_replay)

    report = subparsers.add_parser("rig-report",
                                   help="plot a rig log: grasp probabilities and tensions")
    report.add_argument("log", type=input_file, help="LCM log written by rbp rig-run")
    report.add_argument("-o", "--output", required=True, help="picture to write (.png, .pdf)")
    report.add_argument("--dpi", type=int, default=120,
                        help="the picture's resolution, 20 to 600 dots per inch (default 120)")
    report.set_defaults(func=cmd_rig_report)


def _check_phase(plan: dict, index: int, path: Path) -> None:
    """--phase names a body phase of the plan (systems.rig_interface.body_phase's rule and
    words, checked on the plan file's object before any heavy import)."""
    from rbp.commands.common import UserError

    phases = plan["phases"]
    if not 0 <= index < len(phases):
        have = ("no phases" if not phases else "1 phase (0)" if len(phases) == 1
                else f"{len(phases)} phases (0..{len(phases) - 1})")
        raise UserError(f"{path}: phases[{index}]: no such phase; the plan has {have}")
    if phases[index]["kind"] != "body":
        raise UserError(f"{path}: phases[{index}].kind: a {phases[index]['kind']} phase; the "
                        "rig runs body phases only (its anchors are fixed)")


def _summary(record, stance_ids) -> list[str]:
    lines = []
    for i, anchor in enumerate(stance_ids):
        k = int(record.p_grasp[:, i].argmin())
        lines.append(f"  boom {i} -> {one_line(anchor)}: min P = {record.p_grasp[k, i]:.5f} at "
                     f"t = {record.time[k]:.2f} s (force {record.force[k, i]:.2f} N, pull "
                     f"angle {math.degrees(record.pull_angle[k, i]):+.1f} deg)")
    return lines


def cmd_rig_run(args: argparse.Namespace) -> int:
    from rbp.commands.common import (
        UserError,
        check_output,
        check_seed,
        read_plan,
        refuse_wrong_plan,
        warn_unverified,
    )

    if not MIN_PERIOD <= args.period <= MAX_PERIOD:  # 1e-9 sent commands without end
        raise UserError(f"--period: must be {MIN_PERIOD:g} to {MAX_PERIOD:g} s between "
                        f"commands, got {args.period:g}")
    check_seed(args.seed)
    if args.sim_rig and not args.lcm_url.startswith("memq://"):  # as run_rig, before imports
        raise UserError(f"--lcm-url: the simulated rig runs in-process on memq://, not on "
                        f"{args.lcm_url!r}")
    check_lcm_url(args.lcm_url)
    # a folder, an unwritable place or the plan itself, before the run
    check_output(args.log, "--log", inputs={"the plan's file": args.plan})
    path = Path(args.plan)
    plan = read_plan(path)
    # a plan of no route: a failed outcome (1), as rbp simulate says; its phases, if any (a
    # route whose motion failed), were flown. A partial climb is a verified climb to fly.
    if not plan["success"] and plan.get("partial") is None:
        print(one_line(f"error: {path}: success: the plan found no route ({plan['reason']}); "
                       "nothing to fly"), file=sys.stderr)
        return EXIT_FAILED
    _check_phase(plan, args.phase, path)  # before the verifier's imports (1.4 s, 170 MB)
    # executes: a footstep plan's straight motion, which rig-run commands, is verified too
    if refuse_wrong_plan(plan, path, getattr(args, "verify", True), executes=True,
                         scenario=getattr(args, "scenario", None)):
        return EXIT_FAILED  # before any LCM traffic
    # imported once the plan is read: they take 80 MB, a refused plan's reading its own
    from systems.rig import RigSimConfig
    from systems.rig_interface import RigInputError, RigLcmConfig, run_rig

    config = RigLcmConfig(url=args.lcm_url, period=args.period)
    sim = RigSimConfig(seed=args.seed) if args.sim_rig else None
    try:
        run = run_rig(plan, args.phase, config, args.log, sim_rig=sim,
                      plan_source=f"{path.name} phase {args.phase}",
                      accepted=None if getattr(args, "verify", True)
                      else lambda: warn_unverified(path),
                      check_rates=getattr(args, "verify", True))
    except RigInputError as e:
        where = "" if (e.field or "").startswith("--") else f"{path}: "
        raise UserError(f"{where}{e}") from None
    stance = plan["phases"][args.phase]["stance"]
    print(one_line(f"{path}: phase {args.phase} on {run.lcm_url}: {run.commands} commands "
                   f"sent, {run.statuses} statuses received; wrote {run.log}"))
    for line in run.safety.messages(config):  # what the safety guards did, if anything
        print(f"  safety: {line}")
    if not len(run.live.time):
        print("  no status received: is the rig on this bus?")
        return EXIT_FAILED
    print("\n".join(_summary(run.live, stance)))
    return EXIT_OK


def _replay(log_path: str):
    from rb_drake.input_files import InputFileError, check_input_file
    from rbp.commands.common import UserError
    from systems.rig_log import RigInputError, replay_log  # no Drake: a bad log is refused light

    path = Path(log_path)
    try:
        check_input_file(path)  # a FIFO, a device or a huge file is refused before reading
    except InputFileError as e:
        raise UserError(f"{path}: {e.field}: {e.reason}") from None
    try:
        return replay_log(path)
    except RigInputError as e:
        raise UserError(f"{path}: {e}") from None


def cmd_rig_replay(args: argparse.Namespace) -> int:
    import numpy as np

    log = _replay(args.log)
    rec = log.replay
    # a log's texts are printed escaped: a newline in one could forge an `error:` line
    print(one_line(f"{args.log}: {log.scenario.name}, {log.plan_source or 'rig run'}: "
                   f"{len(log.command_time)} commands, {len(rec.time)} statuses"))
    if len(rec.time):
        print("\n".join(_summary(rec, log.stance_ids)))
        print(f"  min P(all grasps) = {float(np.prod(rec.p_grasp, axis=1).min()):.5f}")
    return EXIT_OK


def cmd_rig_report(args: argparse.Namespace) -> int:
    from rb_drake.files import atomic_save_figure
    from rbp.commands.common import UserError, check_dpi, check_output
    from systems.rig_log import RigLcmConfig, report_figure  # matplotlib once the log is read

    check_dpi(args.dpi)
    check_output(args.output, picture=True, inputs={"the log's file": args.log})
    log = _replay(args.log)
    if not len(log.replay.time):
        channel = RigLcmConfig().status_channel
        raise UserError(f"{args.log}: {channel}: no status messages to plot")
    atomic_save_figure(report_figure(log), args.output, dpi=args.dpi)
    print(one_line(f"wrote {args.output}"))
    return EXIT_OK
