"""Entry point of the ``motion-style`` command.

Each subcommand lives in its own module ``motion_style_ros/cli/<name>.py`` with one function::

    def add_parser(subparsers):
        p = subparsers.add_parser("<name>", help="...", description="...")
        p.add_argument(...)
        p.set_defaults(func=run)

    def run(args) -> int: ...

The module is imported to build the parser, so it must stay light at import time: import torch,
onnxruntime, rclpy, matplotlib and the like inside ``run()``, never at module level
(``motion-style --help`` must stay fast; test/test_package.py checks it).

User mistakes are reported by raising ``motion_style_ros.errors.MotionStyleError`` (or an
``OSError`` such as ``FileNotFoundError``, or a ``ValueError``): main() prints
``motion-style: error: <message>`` and exits with 2, no traceback. ``--traceback`` (or
MOTION_STYLE_TRACEBACK=1) shows the traceback instead.
"""

import argparse
import importlib
import importlib.util
import os
import sys

from motion_style_ros import __version__
from motion_style_ros.errors import MotionStyleError

PROG = "motion-style"

# Subcommand modules, in the order `--help` lists them. A name whose module does not exist yet is
# skipped, so a planned subcommand can be listed here before its module lands.
SUBCOMMANDS = (
    "demo",      # built-in demo: synthetic performer -> stylizer -> outputs
    "data",      # dataset unpacking, indexing, inspection
    "stylize",   # restyle a BVH clip offline
    "perform",   # sample new motion of a style from an SAAE into a BVH file
    "retarget",  # retarget motion between skeletons
    "description",  # the canonical skeleton as a URDF (RViz)
    "train",     # train models (torch)
    "eval",      # metrics and baselines
    "render",    # plots / videos of motion
    "bench",     # latency and throughput
    "warmup",    # compile the stream kernels ahead of the first node start
    "style",     # enrol styles of your own (style bank)
    "robot",     # stylized motion on a humanoid robot (URDF)
    "version",   # print versions
)


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line on stderr, exit code 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def available_subcommands():
    """Names in SUBCOMMANDS whose module exists."""
    return [name for name in SUBCOMMANDS
            if importlib.util.find_spec(f"{__package__}.{name}") is not None]


def build_parser():
    parser = _Parser(
        prog=PROG,
        description="Restyle human motion capture while it streams (ROS 2, VMC/OSC, bags, BVH).",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    parser.add_argument("--traceback", action="store_true",
                        help="show the full traceback on errors (also MOTION_STYLE_TRACEBACK=1)")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in available_subcommands():
        importlib.import_module(f"{__package__}.{name}").add_parser(subparsers)
    return parser


def _describe(exc):
    if isinstance(exc, OSError) and exc.filename:
        return f"{exc.strerror or type(exc).__name__}: {exc.filename}"
    return str(exc) or type(exc).__name__


def main(argv=None):
    """Run ``motion-style``; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        return int(args.func(args) or 0)
    except BrokenPipeError:  # output piped into `head` and the like (an OSError: caught first)
        sys.stderr.close()
        return 141
    except (MotionStyleError, OSError, ValueError) as exc:  # OSError: a path that is a folder, ...
        if args.traceback or os.environ.get("MOTION_STYLE_TRACEBACK"):
            raise
        print(f"{PROG}: error: {_describe(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
