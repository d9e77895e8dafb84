"""`rta-attitude analyze BAG [--compare BAG2] [--animate]`: summary, verdict, figure and boresight sky map of a
recorded run (`recording.analysis`, `recording.plots`, `recording.skymap`), optionally beside a second run,
and an animation of its attitude scene (`recording.scene`). The exit status is BAG's verdict (0 SAFE, 2
UNSAFE unless --allow-unsafe, 1 bad input: `cli.main`); BAG2 is a reference (often a run without RTA,
unsafe by design) and does not count."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from rta_attitude.cli.main import add_verdict_arguments, verdict_status


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of `rta-attitude analyze`."""
    parser.add_argument("bag", type=Path, help="MCAP file (or rosbag2 directory) recorded from a run")
    parser.add_argument("--out", type=Path, default=Path("out/analyze"), help="output directory")
    parser.add_argument("--compare", type=Path, default=None, metavar="BAG2",
                        help="a second run (e.g. without RTA) to overlay and tabulate against the first")
    parser.add_argument("--namespace", default=None, help="namespace of the run's topics (default: found in the bag)")
    parser.add_argument("--scenario", default=None,
                        help="scenario of the run (names the report, sets its slack weights; default: recorded)")
    parser.add_argument("--config", type=Path, default=None,
                        help="parameter YAML of the run (default: $RTA_ATTITUDE_CONFIG or the package's)")
    parser.add_argument("--no-plot", action="store_true", help="skip the PNG figures (figure.png, skymap.png)")
    parser.add_argument("--animate", nargs="?", const="scene.gif", default=None, metavar="FILE",
                        help="also render the attitude scene in the Hill frame as an animation (FILE.gif, or .mp4 "
                             "with ffmpeg; default scene.gif in --out; the first bag)")
    parser.add_argument("--frames", type=int, default=200, help="frames of the animation, evenly over the run (200)")
    add_verdict_arguments(parser, safe="BAG's run violates no non-slacked constraint at a sample or between samples "
                                       "(re-integrated); --compare's BAG2 does not count",
                          unsafe="BAG's run violated a non-slacked constraint")


def run(args: argparse.Namespace) -> int:
    """`rta-attitude analyze`: summary (printed, summary.json), time series, figure and sky map of a bag."""
    from rta_attitude import config as config_module
    from rta_attitude.files import output_folder, write_text
    from rta_attitude.recording.analysis import load_run, resolve_bag_path
    from rta_attitude.recording.summary import (
        compare_summaries,
        format_bag_lines,
        format_comparison,
        label,
        summarize_run,
        write_timeseries,
    )
    from rta_attitude.simulation.metrics import format_summary

    if args.animate is not None:  # a bad name fails before any work
        from rta_attitude.recording.scene import check_animation

        check_animation(Path(args.animate), args.frames)

    for p in [args.bag, *([args.compare] if args.compare is not None else [])]:
        resolve_bag_path(p)  # check inputs first
    cfg = config_module.load(args.config)
    with output_folder(args.out) as out:  # a bag that fails to load leaves no empty folder
        t0 = time.perf_counter()
        run_a = load_run(args.bag, cfg, args.namespace, args.scenario)
        summary_a = summarize_run(run_a, cfg)
        runs = [(run_a.label, run_a)]
        summary_b = None
        if args.compare is not None:
            run_b = load_run(args.compare, cfg, args.namespace, args.scenario)
            summary_b = summarize_run(run_b, cfg)
            runs.append((run_b.label, run_b))
            if run_b.label == run_a.label:  # same kind of run: tell them apart by file
                runs = [(f"{r.label} [{r.path.stem}]", r) for _, r in runs]
        wall = time.perf_counter() - t0
        write_text(out / "summary.json", json.dumps(summary_a, indent=2) + "\n")
        write_timeseries(run_a, out / "timeseries.npz")
        print(format_summary(summary_a))
        print(format_bag_lines(summary_a))
        written = [out / "summary.json", out / "timeseries.npz"]
        if summary_b is not None:
            rows = compare_summaries(summary_a, summary_b)
            write_text(out / "summary_compare.json", json.dumps(summary_b, indent=2) + "\n")
            write_text(out / "comparison.json", json.dumps(
                {"a": str(run_a.path), "b": str(runs[1][1].path), "rows": rows}, indent=2) + "\n")
            print()
            print(format_summary(summary_b))
            print(format_bag_lines(summary_b))
            print()
            print(format_comparison(rows, label(summary_a), label(summary_b)))
            written += [out / "summary_compare.json", out / "comparison.json"]
        if not args.no_plot:
            from rta_attitude.recording.plots import plot_runs
            from rta_attitude.recording.skymap import plot_skymap

            title = f"{run_a.scenario}: " + " vs ".join(label for label, _ in runs) + \
                f" (from {' and '.join(r.path.name for _, r in runs)})"
            written.append(plot_runs(runs, cfg, out / "figure.png", title))
            written.append(plot_skymap(runs, cfg, out / "skymap.png", title))
        if args.animate is not None:
            from rta_attitude.recording.scene import animate_scene

            written.append(animate_scene(run_a, cfg, out / args.animate, f"{run_a.scenario} ({run_a.path.name})",
                                         frames=args.frames))
    print(f"wrote {', '.join(str(p) for p in written)} (bags read and analysed in {wall:.2f} s)")
    return verdict_status(summary_a["safe"], args.allow_unsafe,
                          f"{args.bag} violated {', '.join(summary_a['violated'])}")


__all__ = ["add_arguments", "run"]
