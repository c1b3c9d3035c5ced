"""``motion-style warmup``: compile the stream kernels now, so that the first node start does not."""


def add_parser(subparsers):
    p = subparsers.add_parser(
        "warmup", help="compile the stream kernels (numba; once per install)",
        description="Compile every kernel of the package's core arithmetic (numba, cached on disk beside "
                    "the package or in ~/.cache/numba; 15-45 s on a small machine, once per "
                    "install), so that the first node or session start loads them instead. `make venv` "
                    "runs it; run it after a colcon build too.")
    p.set_defaults(func=run)


def run(args) -> int:
    from motion_style_ros.runtime.warmup import warm_kernels

    print(f"stream kernels ready in {warm_kernels():.1f} s")
    return 0
