"""launch/stylizer.launch.py against the package it starts, and the launch_testing tests.

The first tests read the launch file's syntax tree: every executable it starts is a console script
of setup.py, and every parameter it sets or its YAML files hold is one the node declares. The
others run the real launch service and ``launch_test`` (``launch``, ``launch_ros`` and
``launch_testing`` are not on PyPI: ``make venv`` installs them from ``../shared/ros``) on the
package installed into an ament prefix as colcon installs it (conftest's ``ros_cli``). The ROS
commands a user types are test_ros_cli.py's.
"""

import ast
import re
import threading
import time
from pathlib import Path

import pytest
import yaml
from onnx_fixtures import recurrent_model

ROOT = Path(__file__).resolve().parents[1]
LAUNCH = ROOT / "launch" / "stylizer.launch.py"


def declared(node: str) -> set[str]:
    """Parameter names a node declares (every node declares through ``self.param("name", ...)``,
    the QoS ones through ``self.qos("prefix", ...)`` as ``prefix_reliability`` and ``prefix_depth``,
    and ``self.stream_qos()`` as ``qos_...``; nodes/__init__.py defines both)."""
    source = (ROOT / "motion_style_ros" / "nodes" / f"{node}.py").read_text()
    prefixes = re.findall(r'self\.qos\(\s*"(\w+)"', source) + ["qos"] * ("self.stream_qos(" in source)
    table = set()
    if node == "stylizer":  # the stylizer declares its table (runtime.stylizer_settings)
        from motion_style_ros.runtime.stylizer_settings import NAMES

        table = set(NAMES)
    return (set(re.findall(r'self\.param\(\s*"(\w+)"', source)) | table
            | {f"{p}_{kind}" for p in prefixes for kind in ("reliability", "depth")})


def node_calls(tree: ast.Module) -> dict[str, dict[str, ast.expr]]:
    """Keyword arguments of the launch file's ``Node(...)`` calls of this package by executable
    (robot_state_publisher, the one other package's node, aside)."""
    constants = {n.targets[0].id: n.value for n in tree.body
                 if isinstance(n, ast.Assign) and isinstance(n.targets[0], ast.Name)}
    calls = {}
    for call in ast.walk(tree):
        if isinstance(call, ast.Call) and getattr(call.func, "id", None) in ("Node", "LifecycleNode"):
            kwargs = {k.arg: k.value for k in call.keywords}
            if isinstance(kwargs.get("name"), ast.JoinedStr):  # workers:=N's stylizer_<k>
                continue
            package = kwargs["package"]
            if isinstance(package, ast.Constant) and package.value == "robot_state_publisher":
                continue
            assert ast.literal_eval(constants.get(getattr(package, "id", None), package)) == "motion_style_ros"
            calls[ast.literal_eval(kwargs["executable"])] = kwargs
    return calls


def yaml_parameters(path: Path, node: str) -> set[str]:
    data = yaml.safe_load(path.read_text())
    assert list(data) == [f"/**/{node}"], "the key must match the node in any namespace"
    return set(data[f"/**/{node}"]["ros__parameters"])


def test_launch_starts_console_scripts_of_the_package():
    tree = ast.parse(LAUNCH.read_text())
    setup = (ROOT / "setup.py").read_text()
    calls = node_calls(tree)
    assert set(calls) == {"learned_performer", "stylizer", "stylizer_managed", "vmc_bridge", "synthetic_performer"}
    for executable, kwargs in calls.items():
        assert re.search(rf"'{executable} = motion_style_ros\.nodes\.{executable}:main'", setup)
        assert ast.literal_eval(kwargs["name"]) == executable.removesuffix("_managed")
    assert any(isinstance(n, ast.FunctionDef) and n.name == "generate_launch_description"
               for n in tree.body)


def test_launch_sets_only_declared_parameters():
    tree = ast.parse(LAUNCH.read_text())
    arguments = next(n.value for n in tree.body if isinstance(n, ast.Assign)
                     and getattr(n.targets[0], "id", "") == "STYLIZER_ARGUMENTS")
    set_by_launch = {ast.literal_eval(v) for v in arguments.values}
    assert set_by_launch <= declared("stylizer")
    performer = node_calls(tree)["synthetic_performer"]["parameters"].elts[0]
    assert {ast.literal_eval(k) for k in performer.keys} <= declared("synthetic_performer")


def test_params_files_hold_declared_parameters():
    # every stylizer parameter but target_style, whose default is the model card's neutral style
    assert yaml_parameters(ROOT / "config" / "stylizer.yaml", "stylizer") == declared("stylizer") - {"target_style"}
    assert yaml_parameters(ROOT / "config" / "vmc_bridge.yaml", "vmc_bridge") <= declared("vmc_bridge")
    text = LAUNCH.read_text()
    for name in ("stylizer.yaml", "vmc_bridge.yaml"):
        assert f"[share, 'config', '{name}']" in text


STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]


def test_launch_file_runs_with_the_real_launch_service(tmp_path, ros_cli, monkeypatch):
    # The installed launch file (FindPackageShare) and nodes, from the ament prefix.
    for key in ("AMENT_PREFIX_PATH", "PYTHONPATH"):
        monkeypatch.setenv(key, ros_cli.env[key])
    share = ros_cli.prefix / "share" / "motion_style_ros"
    import rclpy
    from launch import LaunchDescription, LaunchService
    from launch.actions import IncludeLaunchDescription
    from launch.launch_description_sources import PythonLaunchDescriptionSource
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter_client import AsyncParameterClient
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from visualization_msgs.msg import MarkerArray

    model = recurrent_model(tmp_path / "style_erd.onnx", STYLES)
    params = yaml.safe_load((share / "config" / "stylizer.yaml").read_text())
    params["/**/stylizer"]["ros__parameters"]["blend_seconds"] = 0.7  # set by the file only
    (tmp_path / "stylizer.yaml").write_text(yaml.safe_dump(params))
    arguments = {"namespace": "demo", "use_synthetic": "true", "use_vmc": "true", "markers": "true",
                 "model": str(model), "target_style": "elderly", "alpha": "1",
                 "params_file": str(tmp_path / "stylizer.yaml")}
    service = LaunchService()
    service.include_launch_description(LaunchDescription([IncludeLaunchDescription(
        PythonLaunchDescriptionSource(str(share / "launch" / "stylizer.launch.py")),
        launch_arguments=arguments.items())]))
    seen = {}

    def check():
        """Runs beside the launch service (which must own the main thread); shuts it down."""
        context = rclpy.Context()
        rclpy.init(context=context)
        node = rclpy.create_node("launch_check", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        states, markers = [], []
        node.create_subscription(JointState, "/demo/stylized/joint_states", states.append,
                                 qos_profile_sensor_data)
        node.create_subscription(MarkerArray, "/demo/stylized/markers", markers.append,
                                 qos_profile_sensor_data)
        client = AsyncParameterClient(node, "/demo/stylizer")
        deadline = time.monotonic() + 120
        wanted = {"/demo/stylizer", "/demo/synthetic_performer", "/demo/vmc_bridge"}

        def discovered() -> set[str]:
            return {f"{ns.rstrip('/')}/{n}" for n, ns in node.get_node_names_and_namespaces()}

        # every node discovered too: on a busy machine the bridge's participant can show up later
        while time.monotonic() < deadline and not (len(states) > 30 and markers and client.services_are_ready()
                                                   and wanted <= discovered()):
            executor.spin_once(timeout_sec=0.05)
        names = ["model", "target_style", "alpha", "publish_markers", "blend_seconds"]
        future = client.get_parameters(names)
        executor.spin_until_future_complete(future, timeout_sec=30)
        if future.done():
            seen["parameters"] = dict(zip(names, (v.string_value or v.double_value or v.bool_value
                                                  for v in future.result().values)))
        seen["frames"], seen["markers"] = len(states), len(markers)
        seen["nodes"] = discovered()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        service.shutdown()

    threading.Thread(target=check, daemon=True).start()
    assert service.run() == 0  # every process finished cleanly on the shutdown's SIGINT
    assert {"/demo/stylizer", "/demo/synthetic_performer", "/demo/vmc_bridge"} <= seen["nodes"]
    assert seen["frames"] > 30 and seen["markers"] > 0
    assert seen["parameters"] == {"model": str(model), "target_style": "elderly", "alpha": 1.0,
                                  "publish_markers": True, "blend_seconds": 0.7}


LAUNCH_TESTS = sorted((ROOT / "test" / "launch").glob("test_*.launch.py"))


@pytest.mark.parametrize("path", LAUNCH_TESTS, ids=[p.name for p in LAUNCH_TESTS])
def test_launch_testing_file_passes_under_launch_test(path, ros_cli):
    """``launch_test FILE``, as a user or CI runs a launch_testing file: exit 0, and both its active
    and post-shutdown tests ran and passed."""
    out = ros_cli.run("launch_test", str(path), timeout=300)
    text = out.stdout + out.stderr
    assert out.returncode == 0, text
    runs = re.findall(r"^Ran (\d+) tests? in .*\n\n(OK|FAILED.*)$", text, re.M)
    assert len(runs) == 2 and all(result == "OK" and int(n) > 0 for n, result in runs), text


def test_launch_testing_files_exist():
    assert [p.name for p in LAUNCH_TESTS] == ["test_stylizer_bag.launch.py"]


def test_show_args_lists_every_backend_and_the_readme_documents_every_argument(ros_cli):
    """``ros2 launch motion_style_ros stylizer.launch.py --show-args``, as the README shows it: the
    backend's help names every registered backend, and every argument is in the README's list."""
    from motion_style_ros.runtime.backends import BACKENDS

    out = ros_cli.ros2("launch", "motion_style_ros", "stylizer.launch.py", "--show-args")
    assert out.returncode == 0, out.stderr
    helps = dict(re.findall(r"^    '(\w+)':\n        (.*)$", out.stdout, re.M))
    assert {"backend", "reference", "pipelined", "managed", "use_synthetic"} <= set(helps), out.stdout
    assert all(name in helps["backend"] for name in BACKENDS), helps["backend"]
    readme = (ROOT / "README.md").read_text()
    launch_section = readme[readme.index("### Launch"):readme.index("## Layout")]
    assert [a for a in helps if f"`{a}`" not in launch_section] == []
