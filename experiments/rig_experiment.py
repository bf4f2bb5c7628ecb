"""A body movement on the rig (the paper's Fig. 7): each anchor's probability of grasp
maintenance from the measured forces and hinge angles.

Plans the rig's body movement (bundled scenario `rb_drake/data/rig.yaml`, from its start pose to
its goal) with RBP's seed and SCP (`--planner rbp`, default) or as the straight line
(`--planner straight`, `systems.rig.rig_plan`), runs it against the rig over LCM (by default
the simulated rig, in this process on memq://; never the network) and draws Fig. 7 from the
run's log, as `rbp rig-report` does. results.json holds each anchor's probability at the start,
the end and its minimum.

    python -m experiments.rig_experiment --out out/rig
"""

from __future__ import annotations

from typing import Any

from experiments.arguments import OneLineParser, number, path_name, seed_number
from experiments.sweep import check_out_files, machine_info, write_results
from rb_drake.errors import EXIT_FAILED, EXIT_OK


def rbp_body_plan(scn) -> dict[str, Any]:
    """The rig's one body phase through the RBP pipeline: a seed, then SCP."""
    import numpy as np

    from planning.footsteps import FootstepPlan
    from planning.pipeline import PipelineConfig, phase_motions
    from planning.plan import build_motion_plan, build_plan
    from planning.plan_model import plan_dict

    start = np.asarray(scn.start_pose, dtype=float)
    goal = np.array([*scn.goal_position, start[2]])
    # One stance and no regrasp: the footstep plan is given, not searched.
    fp = FootstepPlan(True, "", [tuple(scn.start_stance)], [], start, goal, 0, 0, 0.0)
    config = PipelineConfig()
    timing: dict[str, float] = {}
    motions, failure = phase_motions(scn, fp, config, timing)
    if failure:
        return plan_dict(build_plan(scn, fp, "rbp", timing).failed(
            f"motion planning failed: {failure}"))
    timing["total"] = sum(timing.values())
    return plan_dict(build_motion_plan(scn, fp, motions, "rbp", timing, config.dt))


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    parser = OneLineParser(prog=prog, description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=path_name, default="out/rig_experiment", help="output folder")
    parser.add_argument("--planner", choices=("rbp", "straight"), default="rbp",
                        help="the body movement: RBP seed + SCP (default) or the straight line")
    parser.add_argument("--lcm-url", default="memq://",
                        help="LCM bus of the rig (default memq://, in-process)")
    parser.add_argument("--hardware", action="store_true",
                        help="talk to a real rig on --lcm-url instead of the simulated one")
    parser.add_argument("--seed", type=seed_number, default=0,
                        help="seed of the simulated rig's noise")
    parser.add_argument("--period", type=number(0.001, 60), default=0.1,
                        help="seconds between commands (default 0.1)")
    args = parser.parse_args(argv)
    if not args.period > 0:
        parser.error(f"--period: must be positive, got {args.period}")
    if args.hardware and args.lcm_url.startswith("memq://"):
        parser.error("--hardware: give the rig's bus with --lcm-url udpm://...")
    # the URL before the heavy imports (a wrong one was refused after 1 s and 267 MB)
    from systems.lcm_url import lcm_url_problem

    if not args.hardware and args.lcm_url != "memq://":
        parser.error(f"--lcm-url: the simulated rig runs in-process on memq://, not on "
                     f"{args.lcm_url} (--hardware talks to a real rig)")
    problem = lcm_url_problem(args.lcm_url)
    if problem:
        parser.error(f"--lcm-url: {args.lcm_url!r} {problem}" if problem.startswith("is not")
                     else f"--lcm-url: {args.lcm_url!r}: {problem}")
    check_out_files(args.out, ("plan.json", "rig.lcm", "rig.png", "results.json"))

    import numpy as np

    from planning.plan import write_plan
    from rb_drake.files import atomic_save_figure
    from systems.rig import RigSimConfig, load_rig_scenario, rig_plan
    from systems.rig_interface import run_rig
    from systems.rig_log import RigLcmConfig, replay_log, report_figure

    scn = load_rig_scenario()
    plan = rbp_body_plan(scn) if args.planner == "rbp" else rig_plan(scn)
    path = write_plan(plan, f"{args.out}/plan.json")
    if not plan["success"]:
        print(f"{scn.name}: no body plan ({plan['reason']})")
        return EXIT_FAILED
    sim = None if args.hardware else RigSimConfig(seed=args.seed)
    run = run_rig(plan, 0, RigLcmConfig(url=args.lcm_url, period=args.period),
                  f"{args.out}/rig.lcm", sim_rig=sim, plan_source=f"{args.planner} body plan")
    log = replay_log(run.log)
    rec = log.replay
    if not len(rec.time):
        print(f"no status received on {run.lcm_url}: is the rig on this bus?")
        return EXIT_FAILED
    figure = atomic_save_figure(report_figure(log), f"{args.out}/rig.png", dpi=120)
    anchors = {a: {"start": float(rec.p_grasp[0, i]), "end": float(rec.p_grasp[-1, i]),
                   "min": float(rec.p_grasp[:, i].min()),
                   "max_force": float(rec.force[:, i].max())}
               for i, a in enumerate(log.stance_ids)}
    for a, v in anchors.items():
        print(f"  {a}: P {v['start']:.4f} -> {v['end']:.4f} (min {v['min']:.4f})")
    print(f"wrote {path}\nwrote {run.log}\nwrote {figure}")
    write_results(args.out, {
        "experiment": "rig_experiment", "machine": machine_info(), "params": vars(args),
        "plan": {"p_path": plan["p_path"], "p_min": plan["p_min"],
                 "steps": len(plan["phases"][0]["steps"])},
        "rig": {"simulated": sim is not None, "lcm_url": run.lcm_url, "commands": run.commands,
                "statuses": run.statuses, "duration": float(rec.time[-1] - rec.time[0])},
        "anchors": anchors,
        "min_p_all_grasps": float(np.prod(rec.p_grasp, axis=1).min()),
        "figure": str(figure), "log": str(run.log), "plan_file": str(path)})
    return EXIT_OK


if __name__ == "__main__":
    raise SystemExit(main())
