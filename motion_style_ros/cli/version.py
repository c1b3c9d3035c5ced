"""``motion-style version``: the package version, and with --all the versions it runs on."""

import importlib.metadata
import platform

from motion_style_ros import __version__

_DEPENDENCIES = ("numpy", "scipy", "onnxruntime", "python-osc", "rosbags", "torch", "onnx",
                 "ros-rclpy")


def add_parser(subparsers):
    p = subparsers.add_parser("version", help="print the version",
                              description="Print the motion_style_ros version.")
    p.add_argument("--all", action="store_true",
                   help="also print Python's and the main dependencies' versions")
    p.set_defaults(func=run)


def run(args):
    print(f"motion_style_ros {__version__}")
    if args.all:
        print(f"python {platform.python_version()}")
        for dist in _DEPENDENCIES:
            try:
                version = importlib.metadata.version(dist)
            except importlib.metadata.PackageNotFoundError:
                version = "not installed"
            print(f"{dist} {version}")
    return 0
