"""`robot-calib split`: one bag -> a calibration bag and a hold-out bag (a random share,
or the last share in order or time), written together."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from robot_calib.cli.common import log, robot_files, robot_of
from robot_calib.cli.options import add_force, add_joint_names, add_pair_tolerance, count
from robot_calib.errors import InputError

NAME = "split"
HELP = "one bag -> a calibration bag and a hold-out bag"
ROBOT = None  # --robot's default: DEFAULT_ROBOT


def add_arguments(spl: argparse.ArgumentParser) -> None:
    spl.add_argument("bag", metavar="BAG", help="the bag to split (.mcap)")
    add_joint_names(spl)
    spl.add_argument("--holdout", type=float, default=0.3, help="share held out (0.3)")
    spl.add_argument(
        "--by",
        default="random",
        choices=("random", "order", "time"),
        help="random share (default), or the last share in order or time",
    )
    spl.add_argument("--seed", type=count, default=0, help="seed of the random split (0)")
    spl.add_argument("--calibration-out", help="calibration bag (default BAG.cal.mcap)")
    spl.add_argument("--holdout-out", help="hold-out bag (default BAG.holdout.mcap)")
    add_pair_tolerance(spl)
    add_force(spl)


def main(args: argparse.Namespace) -> int:
    """One bag -> a calibration bag and a hold-out bag (random share, or the last share),
    both in one folder, written together (a failure leaves neither)."""
    from robot_calib.atomic import output_path, staged_outputs
    from robot_calib.bag.read import other_topics
    from robot_calib.bag.write import START_NS, write_measurements
    from robot_calib.flows.bags import read_bags
    from robot_calib.measurements.split import holdout_mask
    from robot_calib.poses import reading_groups

    robot = robot_of(args)
    source = Path(args.bag)
    stem = source.with_suffix("")
    outputs = [
        Path(args.calibration_out or f"{stem}.cal.mcap"),
        Path(args.holdout_out or f"{stem}.holdout.mcap"),
    ]
    for out in outputs:
        output_path(out, "the split bag", [source, *robot_files(args)], args.force)
    if outputs[0].resolve() == outputs[1].resolve():
        raise InputError(f"{outputs[1]}: --calibration-out and --holdout-out name one file")
    if outputs[0].resolve().parent != outputs[1].resolve().parent:
        raise InputError(
            f"{outputs[1]}: write both bags into one folder (they are written together)"
        )
    recording = read_bags([args.bag], robot, args.pair_tolerance, log)
    first, points = recording.points_by_target()  # per pose: every target measured there
    poses = recording.subset(np.isin(np.arange(len(recording)), first))
    held = holdout_mask(poses, args.holdout, args.by, args.seed)
    n = len(recording)
    rotation = recording.by_target(
        np.full((n, 3, 3), np.nan)
        if recording.poses.rotation is None
        else recording.poses.rotation
    )[1]
    sigma = recording.by_target(
        np.full((n, 2), np.nan) if recording.poses.sigma is None else recording.poses.sigma
    )[1]
    stamps = (
        poses.stamp_ns
        if poses.stamp_ns is not None
        else START_NS + np.round(poses.poses.time * 1e9).astype(np.int64)
    )
    temperature = poses.poses.temperature  # the side topic at each pose (as read_bag reads it)
    others = other_topics(source)
    if others:
        log(f"warning: {source}: topics {others} are not measurements: not copied")
    for refs in recording.references:
        if refs.drift is None or not refs.drift.significant:
            log(
                f"note: {source}: reference reflectors {', '.join(refs.names)} are not copied "
                "(they showed no drift to remove)"
            )
        else:
            log(
                f"note: {source}: the tracker's drift that reference reflectors "
                f"{', '.join(refs.names)} show ({refs.drift.max_mm:.4f} mm at most) is removed "
                "from the points written; the references themselves are not copied"
            )
    with staged_outputs(outputs[0].resolve().parent, args.force) as stage:
        counts = [
            write_measurements(
                stage / out.name,
                poses.poses.q[rows],
                points[0][rows],
                robot.joint_names,
                stamps[rows],
                poses.poses.direction[rows],
                extra_points={
                    name: points[k][rows] for k, name in enumerate(recording.target_names) if k
                },
                six_dof={
                    name: (rotation[k][rows], sigma[k][rows])
                    for k, name in enumerate(recording.target_names)
                },
                temperature=None if temperature is None else temperature[rows],
            )
            for out, rows in zip(outputs, (~held, held))
        ]
    group = reading_groups(poses.poses.q)
    for out, role, written, rows in zip(
        outputs, ("calibration", "hold-out"), counts, (~held, held)
    ):
        share = f"; {100 * rows.mean():.0f} % of the measurements" if rows is held else ""
        print(
            f"{out}: {written[next(iter(written))]} measurements at "
            f"{len(np.unique(group[rows]))} distinct poses ({role}, split {args.by}{share}; "
            "the original stamps and approach directions)"
        )
    return 0
