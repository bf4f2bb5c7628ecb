"""`rbp simulate PLAN`: execute a plan in the Drake diagram, then Monte Carlo trials of it.

The deterministic run reports the tracking error and the success probability the simulated
forces imply; `--trials N` draws N stochastic executions (grasp strengths and attach failures)
and reports the success rate with its 95 % Wilson interval beside the plan's p_path, and where
and why climbs failed; `--replan retry|footsteps` continues failed climbs on a new plan and
counts those it saves; `--json FILE` writes the numbers; `--meshcat` shows the climb in Meshcat
on localhost and `--html FILE` saves a self-contained replay. Heavy modules are imported inside
the command so `rbp --help` stays instant.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path
from typing import Any

from experiments.arguments import input_file
from rb_drake.errors import EXIT_FAILED, EXIT_OK, one_line, utf8_text
from rbp.api import MAX_TRIALS


def add_simulate_command(subparsers: Any) -> argparse.ArgumentParser:
    """Register `simulate` on the `rbp` sub-command parsers."""
    p = subparsers.add_parser(
        "simulate", help="execute a plan in a Drake simulation with stochastic grasps",
        description=__doc__.split("\n\n")[0])
    p.add_argument("plan", type=input_file, help="plan file (.json, from rbp plan)")
    p.add_argument("--trials", type=int, default=1000,
                   help="Monte Carlo trials (default 1000; 0: the deterministic run only)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the trials' draws, 0 or more (default 0)")
    p.add_argument("--json", metavar="FILE", help="write the results as JSON")
    p.add_argument("--meshcat", action="store_true",
                   help="show the climb in Meshcat (on localhost; waits for Enter on a terminal)")
    p.add_argument("--html", metavar="FILE", help="save a self-contained HTML replay")
    p.add_argument("--replan", choices=("retry", "footsteps"),
                   help="continue failed climbs on a new plan: re-grasp the same anchor "
                        "(retry) or plan again from where the robot is (footsteps, slow)")
    p.add_argument("--no-verify", dest="verify", action="store_false",
                   help="simulate the plan without verifying it first (experiments only; "
                        "warns on stderr)")
    p.add_argument("--scenario", metavar="CAVE", type=input_file,
                   help="a scenario file or a bundled cave's name: refuse the plan unless it "
                        "was made for this cave and robot (the simulation uses the ones the "
                        "plan embeds)")
    p.set_defaults(func=cmd_simulate)
    return p


def _load_plan(path: Path, verify: bool = True,
               scenario: str | None = None) -> dict[str, Any] | None:
    """The plan to simulate; None when it fails verification (the problems are printed)."""
    from rb_drake.errors import one_line
    from rbp.commands.common import read_plan, refuse_wrong_plan

    plan = read_plan(path)
    # a valid plan of no route: a failed outcome (1), not bad input (2); a partial climb
    # (`rbp plan --partial`) is a verified climb, simulated as `rbp rig-run` flies it
    if not plan["success"] and plan.get("partial") is None:
        print(one_line(f"error: {path}: success: the plan found no route ({plan['reason']}); "
                       "nothing to simulate"), file=sys.stderr)
        return None
    # executes: a footstep plan is flown along the straight lines between its steps, as
    # rig-run commands them, which rbp check leaves unverified (simulate flew one whose booms
    # crossed rock between steps, while rig-run refused it)
    return None if refuse_wrong_plan(plan, path, verify, executes=True,
                                     scenario=scenario) else plan


def _progress(label: str):
    """A one-line progress display on stderr (only on a terminal)."""
    interactive = sys.stderr.isatty()

    def show(text: str) -> None:
        if interactive:
            print(f"\r{label}: {text}\033[K", end="", file=sys.stderr, flush=True)

    def done() -> None:
        if interactive:
            print(file=sys.stderr)

    return show, done


def _simulation_failed(path: Path, error: Exception, where: str) -> int:
    """One line on stderr for a simulation whose solver failed (`SimulationError`, naming the
    phase and time), never a traceback; exit status 1, a failed execution."""
    print(one_line(f"error: {path}: {error}{where}; rbp check {path} tells whether the plan "
                   "fits its cave and robot"), file=sys.stderr)
    return EXIT_FAILED


def cmd_simulate(args: argparse.Namespace) -> int:
    """Run `rbp simulate` (see the module docstring); 0 on success."""
    from rbp.commands.common import (
        UserError,
        check_output,
        check_seed,
        plural,
        warn_unverified,
    )

    check_seed(args.seed)
    plan_input = {"the plan's file": args.plan}
    if args.json:
        check_output(args.json, "--json", inputs=plan_input)
    if args.html:  # a folder here failed after the simulation, naming the temporary file
        check_output(args.html, "--html", picture=None,
                     inputs=plan_input | {"--json's file": args.json})
    if not 0 <= args.trials <= MAX_TRIALS:
        raise UserError(f"--trials: must be 0 to {MAX_TRIALS:,}, got {args.trials}")
    if args.replan and args.trials == 0:
        raise UserError("--replan: replanning continues failed trials; give --trials N > 0")
    path = Path(args.plan)
    plan = _load_plan(path, getattr(args, "verify", True), getattr(args, "scenario", None))
    if plan is None:
        return EXIT_FAILED

    from systems.trajectory import PlanError, PlanTrajectory, plan_scenario

    scn = plan_scenario(plan, str(path))
    try:
        traj = PlanTrajectory(plan, scn)
    except PlanError as e:
        raise UserError(f"{path}: {e}") from None
    if not getattr(args, "verify", True):
        warn_unverified(path)
    # imported once the plan is accepted: a refused plan costs its reading only
    from rb_drake.files import atomic_write_text, output_batch
    from systems.diagram import ClimbSimulator, SimulationError
    from systems.montecarlo import FootstepReplanner, monte_carlo, retry_replanner

    simulator = ClimbSimulator(scn)
    show, done = _progress("simulating")
    start = time.perf_counter()
    try:
        record = simulator.run(traj, progress=lambda k, n, t: show(f"phase {k}/{n}, "
                                                                   f"t = {t:.1f} s"))
    except SimulationError as e:
        done()
        return _simulation_failed(path, e, "")
    done()
    wall = time.perf_counter() - start
    import numpy as np

    err, heading = record.position_error, record.heading_error
    tracking = {"max_position_error": float(err.max()),
                "rms_position_error": float(np.sqrt(np.mean(err**2))),
                "max_heading_error": float(heading.max())}
    p_path, p_sim = plan["p_path"], record.implied_p_path()
    stop = record.failure  # a gripper that could not hand over: the climb goes no further
    flown = (f"{traj.end_time:.1f} s, {plural(len(traj.phases), 'phase')}" if stop is None
             else f"{float(record.times[-1]):.1f} of {traj.end_time:.1f} s, "
                  f"{stop.phase + 1} of {plural(len(traj.phases), 'phase')}")
    print(one_line(f"{path}: simulated {flown}, in {wall:.1f} s; "
                   f"tracking error max {1000 * tracking['max_position_error']:.2f} mm, "
                   f"heading {np.degrees(tracking['max_heading_error']):.2f} deg"))
    if plan.get("partial") is not None:  # its successes climb to its end, not to the goal
        print(f"  a partial climb: it ends {plan['partial']['goal_distance_m']:.2f} m from the "
              "goal; a climb succeeds when it reaches the plan's end")
    if stop is not None:  # said "simulated 182.0 s, 15 phases" of a climb stopped at 87 s
        print(one_line(f"error: {path}: the climb stopped in phase {stop.phase} "
                       f"({traj.phases[stop.phase].kind}) at t = {stop.time:.2f} s: boom "
                       f"{stop.boom} on {stop.anchor} still pulled {stop.draw:.2f} N where its "
                       "gripper opens or closes, so it stayed as it was; no climb gets past it "
                       f"(rbp check {path} tells why)"), file=sys.stderr)
    worst = record.holding_minimum()
    h = int(np.argmin(worst))
    hold = traj.holdings[h]
    print(f"  implied by the simulated forces: p_sim {p_sim:.4f} (plan p_path {p_path:.4f}); "
          f"weakest holding boom {hold.boom} on {hold.anchor} (phases {hold.first}-"
          f"{hold.last}), min P {worst[h]:.4f}")
    # the plan's name as UTF-8 holds it (a name that is not UTF-8 wrote a lone surrogate)
    results: dict[str, Any] = {"plan": utf8_text(str(path)), "trials": args.trials,
                               "successes": None, "rate": None, "ci95": None,
                               "p_path": p_path, "p_sim": p_sim, "seed": args.seed,
                               "tracking": tracking}
    if args.trials > 0:
        replanner, strategy = None, ""
        if args.replan == "retry":
            replanner, strategy = retry_replanner, "retry"
        elif args.replan == "footsteps":
            replanner, strategy = FootstepReplanner(seed=args.seed), "footsteps"
        show, done = _progress("replanning failed climbs")
        try:
            mc = monte_carlo(record, args.trials, args.seed, replanner, strategy, simulator,
                             progress=lambda i, n: show(f"trial {i}/{n}"))
        except SimulationError as e:
            done()
            return _simulation_failed(path, e, " (a Monte Carlo trial's or a replan's run)")
        done()
        lo, hi = mc.ci95
        inside = "inside" if lo <= p_path <= hi else "OUTSIDE"
        print(f"Monte Carlo: {mc.successes}/{mc.trials} climbs succeed: rate {mc.rate:.4f}, "
              f"95% CI [{lo:.4f}, {hi:.4f}]; plan p_path {p_path:.4f} {inside}, "
              f"p_sim {p_sim:.4f}")
        for site in mc.failure_sites()[:5]:
            print(f"  {site['count']:5d} failed at phase {site['phase']} ({site['kind']}), boom "
                  f"{site['boom']} on {site['anchor']}: {site['cause']} (earliest "
                  f"t = {site['earliest_time']:.2f} s)")
        if mc.failures:
            print(f"  first failed trial ({mc.failures[0].trial}): {mc.failures[0].describe()}")
        if mc.replanning is not None:
            r = mc.replanning
            failed = mc.trials - mc.successes
            print(f"replanning ({r.strategy}): {r.saved} of {failed} failed climbs saved "
                  f"({r.attempted} still held on 3 booms, {r.replans} replans); rate "
                  f"{r.rate:.4f}, 95% CI [{r.ci95[0]:.4f}, {r.ci95[1]:.4f}]"
                  + (("; the others: " + ", ".join(f"{n} {what}" for what, n in
                                                   sorted(r.outcomes.items())))
                     if r.outcomes else ""))
        results |= mc.to_json()
        results["plan"], results["tracking"] = utf8_text(str(path)), tracking
    with output_batch() as batch:  # --json and --html, or (a full disk) neither
        if args.json:
            atomic_write_text(args.json, json.dumps(results, indent=1, allow_nan=False) + "\n")
            batch.say(f"wrote {args.json}")
        if args.meshcat or args.html:
            from systems.meshcat_view import (
                MAX_REPLAY_FRAMES,
                natural_frames,
                save_html,
                show_climb,
                start_meshcat,
            )

            # Drake logs "Meshcat listening for connections at ..." at INFO on stderr; the URL
            # is printed below when it is wanted (--meshcat): an accepted --html run prints none
            logging.getLogger("drake").setLevel(logging.WARNING)
            meshcat = start_meshcat()
            frames = show_climb(meshcat, record)
            natural = natural_frames(float(record.times[-1]))
            if natural > MAX_REPLAY_FRAMES:  # the page grew without end with the climb
                batch.say(f"replay: {frames:,} frames spread over the {record.times[-1]:.0f} s "
                          f"climb, at most {MAX_REPLAY_FRAMES:,} (one every 0.2 s of climb "
                          f"would be {natural:,}; the limit keeps an --html page near 45 MB)")
            if args.html:
                save_html(meshcat, args.html)
                batch.say(f"wrote {args.html}")
    if args.meshcat:
        print(f"Meshcat: {meshcat.web_url()}")
        if sys.stdin.isatty():
            try:
                input("press Enter to quit ")
            except EOFError:  # Ctrl-D at the prompt quits as Enter does (a traceback)
                print(file=sys.stderr)
    return EXIT_OK if stop is None else EXIT_FAILED  # a climb that cannot go on failed
