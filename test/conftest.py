"""Fixtures shared by the test modules. Keep it small: add a fixture here only when several
test modules need it."""

import os
import signal
import subprocess
from pathlib import Path

import pytest

# A suite started in the background of a shell without job control (`make test &`) inherits Ctrl-C
# ignored, and so would every node and `ros2 launch` it starts: the tests that press Ctrl-C on them
# would wait for nothing. Python's own handler here makes the children start with the default.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# launch_testing files (test/launch/test_*.launch.py) run with `launch_test`, not as pytest modules:
# test_launch.py runs them so.
collect_ignore_glob = ["launch/*.launch.py"]

# ROS 2 in tests: discovery stays on the loopback interface (by default Fast DDS multicasts
# discovery on every interface) and in a domain of this test process's own. Set at import, so
# rclpy used in-process and every subprocess started from the tests inherit it.
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_STATIC_PEERS", None)
os.environ["ROS_DOMAIN_ID"] = str(1 + os.getpid() % 100)


@pytest.fixture(scope="session", autouse=True)
def stream_kernels():
    """The compiled kernels ready (numba's disk cache written) before any test starts a node
    process: one that compiled them itself would spend its start-up timeouts on it."""
    from motion_style_ros.runtime.warmup import warm_kernels

    warm_kernels()


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    """Environment for a subprocess that uses rclpy: pass it as ``subprocess.run(..., env=ros_env)``.

    The ROS 2 PyPI wheels need LD_LIBRARY_PATH to point at their shared libraries;
    ros-wheels-bootstrapper (a .pth file) sets it by re-executing Python at start-up unless
    _ROS_WHEELS_BOOTSTRAP_COMPLETE is set. The guard is dropped here so that the child Python
    sets it up for its own environment whatever the parent did. ROS logs go to a temporary folder
    of the test module.
    """
    env = dict(os.environ)
    env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
    env["ROS_LOG_DIR"] = str(tmp_path_factory.mktemp("ros_log"))
    env["PYTHONUNBUFFERED"] = "1"
    return env


@pytest.fixture
def listener():
    """A test node in its own rclpy context (``test/ros_helpers.py``)."""
    from ros_helpers import Listener

    node = Listener()
    yield node
    node.close()


@pytest.fixture
def start(ros_env):
    """Start ``motion_style_ros.nodes.<name>`` with ROS parameters; stopped (SIGINT, then kill)."""
    from ros_helpers import start_node, stop

    procs = []

    def start_one(name, **params):
        procs.append(start_node(name, ros_env, **params))
        return procs[-1]

    yield start_one
    for proc in procs:
        stop(proc)


@pytest.fixture(scope="session")
def datasets():
    """Root of the unpacked motion datasets, as ``../shared/datasets/unpack.sh`` (run from the
    project root) prints it; unpacks on first use, skips the test where the datasets are absent."""
    script = Path(__file__).resolve().parents[1].parent / "shared" / "datasets" / "unpack.sh"
    if not script.is_file():
        pytest.skip(f"motion datasets not available ({script} not found)")
    out = subprocess.run(["bash", str(script)], capture_output=True, text=True, check=True)
    return Path(out.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def small_model(tmp_path_factory):
    """A random-weight stand-in for Style-ERD with the real ONNX interface and three styles (active,
    elderly, normal; ``onnx_fixtures.py``), for tests of node behaviour that must not depend on the
    shipped model."""
    from onnx_fixtures import recurrent_model

    return recurrent_model(tmp_path_factory.mktemp("small_model") / "style_erd.onnx",
                           ["active", "elderly", "normal"])


@pytest.fixture(scope="session")
def ros_cli(tmp_path_factory, stream_kernels):
    """The package installed into a scratch ament prefix as colcon installs it (once per session),
    and the user's ``ros2``/``launch_test`` commands against it (``test/ros_cli.py``)."""
    from ros_cli import RosCli, install, require_tools, seed_kernel_cache

    require_tools()
    base = tmp_path_factory.mktemp("ament")
    install(base / "install", base / "build")
    seed_kernel_cache(base / "install")
    (base / "log").mkdir()
    cli = RosCli(base / "install", base / "log")
    yield cli
    cli.close()
