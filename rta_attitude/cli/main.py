"""`rta-attitude`: the command line. Every subcommand checks its inputs first, prints one
`ERROR: ...` line and returns 1 on bad input or a file error (no traceback).

Exit status (docs/decisions.md, "Exit codes"): 0 done (and, for simulate, analyze and montecarlo,
SAFE); 1 the command could not do its work: bad input (argument errors included), a file error, one
`ERROR: ...` line on stderr; 2 UNSAFE (simulate, analyze, montecarlo: the verdict is UNSAFE, every
output written; `--allow-unsafe` exits 0 instead); 130 interrupted.

    rta-attitude simulate --scenario paper-example [--no-rta] [--preset robust|paper] --out DIR
    rta-attitude check-config [--config FILE]
    rta-attitude launch ...        (the nodes over DDS: cli/launch.py)
    rta-attitude montecarlo ...    (cli/montecarlo.py)
    rta-attitude viability ...     (cli/viability.py)
    rta-attitude analyze BAG ...   (cli/analyze.py)
    rta-attitude replay BAG        (cli/replay.py)
    rta-attitude topics | echo     (cli/topics.py)
    rta-attitude foxglove          (cli/foxglove.py)

Each subcommand is one module of this package with `add_arguments(parser)` and `run(args) -> int`;
their imports are light (the core, numba and rclpy load in `run`), so `--help` and argument errors
answer at once.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Callable
from typing import Any, NoReturn

from rta_attitude.errors import RtaError

EXIT_OK = 0
"""Done; for simulate, analyze and montecarlo: the verdict is SAFE (or --allow-unsafe)."""
EXIT_ERROR = 1
"""The command could not do its work: bad input, a file error (one `ERROR: ...` line on stderr)."""
EXIT_UNSAFE = 2
"""simulate, analyze, montecarlo: the run(s) finished and every output is written, the verdict is UNSAFE."""
EXIT_INTERRUPTED = 130
"""Ctrl-C (128 + SIGINT, as shells report it)."""
EXIT_STATUS_HELP = (
    (EXIT_OK, "SAFE: {safe}"),
    (EXIT_ERROR, "the command could not run: bad input or a file error, one 'ERROR: ...' line on stderr"),
    (EXIT_UNSAFE, "UNSAFE: {unsafe}; every output is written (--allow-unsafe: exit 0 instead)"),
    (EXIT_INTERRUPTED, "interrupted"),
)
"""The epilog of the commands that give a verdict (`add_verdict_arguments`)."""

SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "simulate": ("simulate", "run a scenario in process (no DDS); summary, time series, figure"),
    "check-config": ("check_config", "validate a parameter file and print what it sets"),
    "launch": ("launch", "run the closed loop as ROS 2 nodes over DDS, record an MCAP bag"),
    "montecarlo": ("montecarlo", "the paper's Monte Carlo of the filter from Latin-hypercube states"),
    "viability": ("viability", "the viability oracle: is a state recoverable? (states or a Monte Carlo's failures)"),
    "analyze": ("analyze", "summary and figure of a recorded MCAP bag"),
    "replay": ("replay", "republish a bag's messages over DDS with /clock"),
    "topics": ("topics", "list live ROS topics with types, publishers and rates"),
    "echo": ("topics", "print the messages of one live topic as YAML"),
    "foxglove": ("foxglove", "serve the live ROS topics to Foxglove/Lichtblick over WebSocket (raw CDR)"),
}
"""Subcommand -> (module of rta_attitude.cli, help)."""


class Parser(argparse.ArgumentParser):
    """argparse with the CLI's error contract: a bad argument is one `ERROR: ...` line and exit 1, like every
    other bad input (argparse's own is a usage block and exit 2, which is UNSAFE here)."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_ERROR, f"ERROR: {self.prog}: {' '.join(message.split())} (see {self.prog} --help)\n")


def add_verdict_arguments(parser: argparse.ArgumentParser, safe: str, unsafe: str) -> None:
    """`--allow-unsafe` and the exit-status epilog of a command that gives a verdict; safe, unsafe: what
    each verdict means for this command."""
    parser.add_argument("--allow-unsafe", action="store_true",
                        help=f"exit 0 even when the verdict is UNSAFE (default: exit {EXIT_UNSAFE}: {unsafe})")
    import textwrap

    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = "exit status:\n" + "\n".join(
        textwrap.fill(text.format(safe=safe, unsafe=unsafe), width=88, initial_indent=f"  {code:<5}",
                      subsequent_indent=" " * 7) for code, text in EXIT_STATUS_HELP)


def verdict_status(safe: bool, allow_unsafe: bool, what: str) -> int:
    """The exit status of a finished command with this verdict; on UNSAFE, one line on stderr says why the
    status is not 0 (what: the verdict's detail)."""
    if safe:
        return EXIT_OK
    if allow_unsafe:
        return EXIT_OK
    print(f"UNSAFE: {what} (exit status {EXIT_UNSAFE}; --allow-unsafe exits 0)", file=sys.stderr)
    return EXIT_UNSAFE


def build_parser() -> tuple[argparse.ArgumentParser, dict[str, Callable[[argparse.Namespace], int]]]:
    """The argument parser and the handler of each subcommand."""
    parser = Parser(prog="rta-attitude", description=__doc__.split("\n")[0])
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    handlers: dict[str, Callable[[argparse.Namespace], int]] = {}
    for name, (module_name, help_text) in SUBCOMMANDS.items():
        module: Any = importlib.import_module(f"rta_attitude.cli.{module_name}")
        p = sub.add_parser(name, help=help_text)
        if module_name == "topics":
            module.add_arguments(p, name)
        else:
            module.add_arguments(p)
        handlers[name] = module.run
    return parser, handlers


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit status."""
    parser, handlers = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    from rta_attitude.kernel_cache import drop_stale_caches

    drop_stale_caches()  # every command may run kernels (simulate, montecarlo, analyze, launch, ...)
    try:
        return int(handlers[args.command](args) or 0)
    except RtaError as exc:
        print(f"ERROR: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except OSError as exc:  # a file error no command anticipated: still one line, not a traceback
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"ERROR: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print("ERROR: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
