"""Packaging and setup: package.xml, setup.py, the motion-style command, the ROS 2 wheels."""

import json
import os
import re
import runpy
import subprocess
import sys
import textwrap
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

import motion_style_ros

ROOT = Path(__file__).resolve().parents[1]

ROS_EXEC_DEPENDS = [
    "rclpy", "sensor_msgs", "trajectory_msgs", "geometry_msgs", "visualization_msgs",
    "std_msgs", "std_srvs", "rcl_interfaces", "diagnostic_msgs",
]
EXEC_DEPENDS = ROS_EXEC_DEPENDS + ["python3-numpy", "python3-numba", "python3-scipy"]


@pytest.fixture(scope="module")
def package_xml():
    return ET.parse(ROOT / "package.xml").getroot()


@pytest.fixture(scope="module")
def setup_kwargs():
    """The keyword arguments setup.py passes to setuptools.setup(), without building anything."""
    import setuptools

    captured = {}
    cwd = os.getcwd()
    real_setup = setuptools.setup
    setuptools.setup = lambda **kwargs: captured.update(kwargs)
    try:
        runpy.run_path(str(ROOT / "setup.py"), run_name="__main__")
    finally:
        setuptools.setup = real_setup
        os.chdir(cwd)
    assert captured, "setup.py did not call setuptools.setup()"
    return captured


def motion_style_command():
    script = Path(sys.executable).with_name("motion-style")
    if script.exists():
        return [str(script)]
    return [sys.executable, "-m", "motion_style_ros.cli.main"]


def test_package_xml_is_format_3_ament_python(package_xml):
    assert package_xml.tag == "package"
    assert package_xml.get("format") == "3"
    assert package_xml.findtext("name") == "motion_style_ros"
    assert package_xml.findtext("license") == "Apache-2.0"
    assert package_xml.findtext("export/build_type") == "ament_python"
    exec_depends = [e.text for e in package_xml.findall("exec_depend")]
    for dep in EXEC_DEPENDS:
        assert dep in exec_depends, dep
    test_depends = {e.text for e in package_xml.findall("test_depend")}
    assert {"ament_copyright", "ament_flake8", "ament_pep257", "python3-pytest"} <= test_depends


def test_every_ros_package_the_code_imports_is_an_exec_depend(package_xml):
    """rosdep installs what package.xml names: every ROS package the nodes and the launch file
    import (messages, services, launch, rclpy) and PyYAML must be there."""
    imported = set()
    for path in [*(ROOT / "motion_style_ros").rglob("*.py"), *(ROOT / "launch").glob("*.py")]:
        imported |= set(re.findall(r"^\s*(?:from|import) ([a-z_]+)", path.read_text(), re.MULTILINE))
    ros = {m for m in imported if m.endswith(("_msgs", "_srvs", "_interfaces")) or m.startswith(("launch", "rclpy"))}
    assert {"rclpy", "sensor_msgs", "launch_ros"} <= ros  # the scan finds them
    declared = {e.text for e in package_xml.findall("exec_depend")}
    wanted = ros | ({"lifecycle_msgs"} if "rclpy.lifecycle" in "".join(
        p.read_text() for p in (ROOT / "motion_style_ros" / "nodes").glob("*.py")) else set())
    assert wanted - declared == set()
    assert "yaml" not in imported or "python3-yaml" in declared


def test_versions_agree(package_xml, setup_kwargs):
    assert package_xml.findtext("version") == setup_kwargs["version"] == motion_style_ros.__version__


def test_install_requires_has_no_torch_and_no_ros_wheel(setup_kwargs):
    names = [re.split(r"[\s<>=!~;\[]", req, maxsplit=1)[0].lower()
             for req in setup_kwargs["install_requires"]]
    assert names, "install_requires is empty"
    assert "torch" not in names
    assert not [n for n in names if n.startswith("ros-") or n == "rclpy"], names
    assert {"numpy", "numba", "scipy", "onnxruntime", "python-osc", "rosbags"} <= set(names)
    assert "torch==2.13.0" in setup_kwargs["extras_require"]["train"]


def test_setup_installs_ament_marker_package_xml_and_entry_point(setup_kwargs):
    data_files = dict(setup_kwargs["data_files"])
    assert data_files["share/ament_index/resource_index/packages"] == ["resource/motion_style_ros"]
    assert data_files["share/motion_style_ros"] == ["package.xml"]
    for files in data_files.values():
        for f in files:
            assert (ROOT / f).is_file(), f
    assert (ROOT / "resource" / "motion_style_ros").is_file()
    assert "motion_style_ros" in setup_kwargs["packages"]
    assert not [p for p in setup_kwargs["packages"] if p.split(".")[0] == "test"]
    scripts = setup_kwargs["entry_points"]["console_scripts"]
    assert "motion-style = motion_style_ros.cli.main:main" in scripts


def test_every_ros_exec_depend_has_a_pinned_pypi_wheel():
    text = (ROOT / "requirements-ros-wheels.txt").read_text()
    pins = dict(re.findall(r"^(ros-[a-z0-9-]+)==(\S+)", text, flags=re.M))
    assert "ros-wheels-bootstrapper" in pins
    for dep in ROS_EXEC_DEPENDS:
        assert "ros-" + dep.replace("_", "-") in pins, dep


def test_requirements_dev_pins_cpu_torch_first():
    lines = [ln.split("#")[0].strip()
             for ln in (ROOT / "requirements-dev.txt").read_text().splitlines()]
    lines = [ln for ln in lines if ln]
    assert lines[0] == "torch==2.13.0"
    assert "-r requirements-ros-wheels.txt" in lines


def test_cli_help_exits_0():
    proc = subprocess.run(motion_style_command() + ["--help"], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "demo" in proc.stdout and "version" in proc.stdout


def test_style_add_help_says_enrolment_is_experimental_with_its_figure():
    proc = subprocess.run(motion_style_command() + ["style", "add", "--help"], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    text = " ".join(proc.stdout.split())
    assert "Experimental:" in text and "recognised on 0-10 % of outputs" in text


def test_cli_usage_error_is_one_line_exit_2():
    proc = subprocess.run(motion_style_command() + ["demo", "--bogus"], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "error:" in lines[0] and "--bogus" in lines[0]
    assert "Traceback" not in proc.stderr + proc.stdout


def test_cli_user_errors_are_one_line_exit_2(monkeypatch, capsys):
    from motion_style_ros.cli import main as cli
    from motion_style_ros.errors import MotionStyleError

    def fail(exc):
        def run(args):
            raise exc
        return run

    for exc, expected in [
        (MotionStyleError("unknown style 'sad'"), "unknown style 'sad'"),
        (FileNotFoundError(2, "No such file or directory", "take.bvh"), "take.bvh"),
        (ValueError("alpha must be in [0, 1]"), "alpha must be in [0, 1]"),
    ]:
        monkeypatch.setattr("motion_style_ros.cli.demo.run", fail(exc))
        assert cli.main(["demo"]) == 2
        err = capsys.readouterr().err
        assert err == f"motion-style: error: {err.split('error: ', 1)[1]}"
        assert expected in err and err.count("\n") == 1
    monkeypatch.setenv("MOTION_STYLE_TRACEBACK", "1")
    with pytest.raises(ValueError):
        cli.main(["demo"])


def test_cli_version(capsys):
    from motion_style_ros.cli import main as cli

    assert cli.main(["version"]) == 0
    assert capsys.readouterr().out.strip() == f"motion_style_ros {motion_style_ros.__version__}"


def test_cli_help_imports_nothing_heavy():
    code = textwrap.dedent("""
        import json, sys
        from motion_style_ros.cli import main
        try:
            main.main(["--help"])
        except SystemExit:
            pass
        heavy = ("torch", "onnx", "onnxruntime", "rclpy", "matplotlib", "scipy", "numba")
        sys.stderr.write(json.dumps([m for m in heavy if m in sys.modules]))
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stderr) == []


ROS_PROGRAM = textwrap.dedent("""
    import time

    import rclpy
    from rclpy.node import Node
    # Every ROS message package that package.xml names must import.
    import diagnostic_msgs.msg, geometry_msgs.msg, rcl_interfaces.msg, std_msgs.msg  # noqa
    import std_srvs.srv, trajectory_msgs.msg, visualization_msgs.msg  # noqa
    from sensor_msgs.msg import JointState

    rclpy.init()
    node = Node("motion_style_selftest")
    received = []
    node.create_subscription(JointState, "selftest/joint_states", received.append, 10)
    pub = node.create_publisher(JointState, "selftest/joint_states", 10)
    msg = JointState(name=["Hips_rx", "Spine_ry"], position=[0.25, -1.5])
    msg.header.stamp = node.get_clock().now().to_msg()
    deadline = time.monotonic() + 30.0
    while not received and time.monotonic() < deadline:
        pub.publish(msg)
        rclpy.spin_once(node, timeout_sec=0.1)
    assert received, "no JointState arrived within 30 s"
    got = received[0]
    assert list(got.name) == ["Hips_rx", "Spine_ry"], got
    assert list(got.position) == [0.25, -1.5], got
    assert got.header.stamp == msg.header.stamp
    node.destroy_node()
    rclpy.shutdown()
    print("JOINT_STATE_ROUND_TRIP_OK")
""")


def test_ros2_wheels_publish_and_subscribe(ros_env):
    proc = subprocess.run([sys.executable, "-c", ROS_PROGRAM], capture_output=True, text=True,
                          timeout=120, env=ros_env, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "JOINT_STATE_ROUND_TRIP_OK" in proc.stdout


WARMED = textwrap.dedent("""
    import importlib, pkgutil, sys
    sys.path.insert(0, sys.argv[1])
    import motion_style_ros
    assert motion_style_ros.__file__.startswith(sys.argv[1]), motion_style_ros.__file__
    from numba.core.registry import CPUDispatcher
    from motion_style_ros.runtime.warmup import warm_kernels
    warm_kernels()
    hits = misses = 0
    for package in ("motion_style_ros.core", "motion_style_ros.io"):
        for info in pkgutil.walk_packages(importlib.import_module(package).__path__, package + "."):
            for f in vars(importlib.import_module(info.name)).values():
                if isinstance(f, CPUDispatcher):
                    hits += sum(f.stats.cache_hits.values())
                    misses += sum(f.stats.cache_misses.values())
    print(hits, misses)
""")


def test_a_colcon_style_install_compiles_the_stream_kernels_into_the_prefix(tmp_path):
    """``setup.py install`` (colcon's ament_python build) compiles the kernels into the install, so
    a node started from it loads every kernel from the cache: the first launch after a build does
    not wait for a compiler."""
    from ros_cli import install, site_packages

    out = install(tmp_path / "install", tmp_path / "build", warm=True)
    assert "motion_style_ros: stream kernels compiled into the install in" in out.stdout, out.stdout[-2000:]
    lib = site_packages(tmp_path / "install")
    started = subprocess.run([sys.executable, "-c", WARMED, str(lib)], cwd=lib, capture_output=True, text=True)
    assert started.returncode == 0, started.stderr
    hits, misses = map(int, started.stdout.split())
    assert hits > 0 and misses == 0, (hits, misses)
