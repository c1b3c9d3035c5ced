"""The ROS user's tools in tests: the package installed into an ament prefix as colcon's
ament_python build installs it, and the real ``ros2`` and ``launch_test`` commands run against it.

``ros2`` and ``launch_test`` (ros2cli, launch, launch_ros, launch_testing) are not on PyPI: ``make
venv`` installs them from ``../shared/ros`` (its ``install.sh``). Where that folder is absent the
tests that need them skip and say so; where it is there, a venv without them is an error (run
``make venv``), so that nothing skips on CI for want of them.

Every command runs with ``AMENT_PREFIX_PATH`` (and ``PYTHONPATH``, as colcon's ``setup.bash`` sets
them) on the scratch prefix, discovery on loopback (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) in a
ROS domain of the test session's own, and ``--no-daemon`` wherever a verb takes it, so that no ros2
daemon outlives a test (the lifecycle test starts a daemon of its own and stops it; ``close`` stops
any left). Without a daemon's cached graph a fresh command has to discover the nodes itself: the
verbs that look a node up get ``--timeout`` (waits until it is found) or ``--spin-time`` (waits that
long), which a loaded 2-core machine needs beyond their 0.5-1 s defaults.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "motion_style_ros"
SHARED_ROS = ROOT.parent / "shared" / "ros" / "install.sh"
BIN = Path(sys.executable).parent
# A domain apart from conftest.py's (1 + pid % 100), which the in-process tests use.
DOMAIN = 101 + os.getpid() % 100
DISCOVERY = "5"  # --timeout: seconds a ros2 param verb waits for the node it is asked about
SPIN = "1.5"  # --spin-time: seconds a verb without --timeout spins to discover the graph
ERROR_LINE = re.compile(r"\[ERROR\]|Traceback|Failed to publish|context is invalid")


def require_tools() -> None:
    """Skip (``../shared/ros`` absent) or fail (present, but ``make venv`` has not installed it)
    unless ``ros2`` and ``launch_test`` are in this venv."""
    if (BIN / "ros2").is_file() and (BIN / "launch_test").is_file():
        return
    if not SHARED_ROS.is_file():
        pytest.skip(f"the ROS 2 launch and CLI tools are not installed and {SHARED_ROS} is absent")
    pytest.fail(f"ros2/launch_test missing from {BIN}: run `make venv` (it runs {SHARED_ROS})")


def install(prefix: Path, work: Path, warm: bool = False) -> subprocess.CompletedProcess:
    """Install the package into ``prefix`` as colcon's ament_python build does (``setup.py ...
    install --prefix P --single-version-externally-managed``; setup.cfg puts the executables in
    ``lib/motion_style_ros`` for ``ros2 run`` and launch). ``warm``: the install compiles the
    kernels into the prefix as a user's does (about 25 s); else :func:`seed_kernel_cache` does
    the tests' installs quicker."""
    work.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, **({} if warm else {"MOTION_STYLE_NO_WARMUP": "1"}))
    out = subprocess.run(
        [sys.executable, "setup.py", "egg_info", "--egg-base", str(work), "build", "--build-base",
         str(work / "build"), "install", "--prefix", str(prefix), "--record", str(work / "record.txt"),
         "--single-version-externally-managed"],
        cwd=ROOT, capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr
    return out


def site_packages(prefix: Path) -> Path:
    return prefix / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"


def seed_kernel_cache(prefix: Path) -> int:
    """Copy the imported package's numba cache (which conftest's ``stream_kernels`` has just made
    current) next to the prefix's copies of the same files; how many files. The install keeps
    the sources' modification times, which is what numba's cache index checks, so the nodes
    started from the prefix load the kernels instead of compiling them (30 s on 2 cores, once per
    install: that first start is measured in docs/ros.md, not in every test run)."""
    import motion_style_ros  # the copy this session imported: the source tree, or an installed one

    imported = Path(motion_style_ros.__file__).resolve().parent
    count = 0
    for cached in imported.rglob("__pycache__/*.nb[ic]"):
        target = site_packages(prefix) / PACKAGE / cached.relative_to(imported)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(cached, target)
        count += 1
    return count


class RosCli:
    """The environment of a user who sourced the install's ``setup.bash``, and their commands."""

    def __init__(self, prefix: Path, log_dir: Path) -> None:
        self.prefix = prefix
        self.log_dir = log_dir
        env = dict(os.environ)
        env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)  # see conftest.ros_env
        env.update(AMENT_PREFIX_PATH=str(prefix),
                   PYTHONPATH=os.pathsep.join([str(site_packages(prefix)), env.get("PYTHONPATH", "")]).rstrip(os.pathsep),
                   PATH=os.pathsep.join([str(BIN), env.get("PATH", "")]),
                   ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(DOMAIN),
                   ROS_LOG_DIR=str(log_dir), PYTHONUNBUFFERED="1")
        env.pop("ROS_STATIC_PEERS", None)
        self.env = env
        self._procs: list[subprocess.Popen] = []

    def executable(self, name: str) -> Path:
        """An installed node executable, as ``ros2 run`` and launch find it."""
        return self.prefix / "lib" / PACKAGE / name

    def run(self, *cmd: str, timeout: float = 60) -> subprocess.CompletedProcess:
        """``cmd`` to its end: its exit code and output."""
        return subprocess.run(list(cmd), env=self.env, capture_output=True, text=True, timeout=timeout,
                              stdin=subprocess.DEVNULL)

    def ros2(self, *args: str, timeout: float = 60) -> subprocess.CompletedProcess:
        return self.run("ros2", *args, timeout=timeout)

    def ros2_graph(self, *args: str, tries: int = 4, until=None, daemon: bool = False, timeout: float = 60):
        """A verb that looks the graph up (``ros2 node list``, ``ros2 lifecycle``, which also wants
        the node's lifecycle services): tried again while what it wants was not discovered yet
        ("Node not found", or ``until(output)`` false), as a user would on a loaded machine. With
        ``--no-daemon`` it spins 1.5, 3, 6, 12 s to discover the graph; with ``daemon`` (a test that
        started one with ``ros2 daemon start`` and stops it) it asks the daemon's graph."""
        for attempt in range(tries):
            options = [] if daemon else ["--no-daemon", "--spin-time", str(float(SPIN) * 2**attempt)]
            out = self.ros2(*args, *options, timeout=timeout)
            if "Node not found" not in out.stdout + out.stderr and (until is None or until(out)):
                break
            time.sleep(0.5)
        return out

    def start(self, *cmd: str, log: str) -> subprocess.Popen:
        """``cmd`` in the background (its own process group), output into ``log_dir/log``."""
        with open(self.log_dir / log, "w") as out:
            proc = subprocess.Popen(list(cmd), env=self.env, stdin=subprocess.DEVNULL, stdout=out,
                                    stderr=subprocess.STDOUT, text=True, start_new_session=True)
        proc.log = self.log_dir / log
        self._procs.append(proc)
        return proc

    def first_message(self, topic: str, msg_type: str, timeout: float = 90, field: str | None = None) -> str:
        """``ros2 topic echo --once`` of ``topic``: the first message as the CLI prints it."""
        cmd = ["topic", "echo", "--no-daemon", "--once", topic, msg_type] + (["--field", field] if field else [])
        out = self.ros2(*cmd, timeout=timeout)
        assert out.returncode == 0, out.stderr
        return out.stdout

    @staticmethod
    def stop(proc: subprocess.Popen, sig: int | None = signal.SIGINT, timeout: float = 30) -> int:
        """Send ``sig`` (Ctrl-C by default; None: none, it has had one) to ``proc`` alone and wait;
        its exit code. A process group still alive after ``timeout`` is killed and the test fails."""
        if sig is not None and proc.poll() is None:
            proc.send_signal(sig)
        try:
            return proc.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            log = proc.log.read_text() if getattr(proc, "log", None) else ""
            pytest.fail(f"{' '.join(proc.args)} did not stop within {timeout} s of its signal; "
                        f"its output:\n{log}")

    def ctrl_c(self, proc: subprocess.Popen, timeout: float = 30) -> int:
        """Ctrl-C in the terminal of ``proc``: SIGINT to its whole process group (``ros2 run`` waits
        for its node to stop; the node gets the signal too); the exit code."""
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
        return self.stop(proc, None, timeout)

    def close(self) -> None:
        """Kill whatever a test left running (its whole process group), and a daemon if one was
        started after all."""
        for proc in self._procs:
            if proc.poll() is None:
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                proc.wait()
        self.ros2("daemon", "stop", timeout=30)


def error_lines(text: str) -> list[str]:
    """Lines of a node's or launch's output that report an error."""
    return [line for line in text.splitlines() if ERROR_LINE.search(line)]
