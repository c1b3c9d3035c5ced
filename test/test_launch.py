"""launch/stylizer.launch.py against the package it starts, without the launch packages.

``launch`` and ``launch_ros`` are not on PyPI, so this reads the launch file's syntax tree: every
executable it starts is a console script of setup.py, and every parameter it sets or its YAML files
hold is one the node declares. How the file was run with the real launch sources is in the README.
"""

import ast
import re
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
LAUNCH = ROOT / "launch" / "stylizer.launch.py"


def declared(node: str) -> set[str]:
    """Parameter names a node declares (every node declares through ``self.param("name", ...)``)."""
    source = (ROOT / "motion_style_ros" / "nodes" / f"{node}.py").read_text()
    return set(re.findall(r'self\.param\(\s*"(\w+)"', source))


def node_calls(tree: ast.Module) -> dict[str, dict[str, ast.expr]]:
    """Keyword arguments of the launch file's ``Node(...)`` calls by executable; checks that each
    starts a node of this package."""
    constants = {n.targets[0].id: n.value for n in tree.body
                 if isinstance(n, ast.Assign) and isinstance(n.targets[0], ast.Name)}
    calls = {}
    for call in ast.walk(tree):
        if isinstance(call, ast.Call) and getattr(call.func, "id", None) == "Node":
            kwargs = {k.arg: k.value for k in call.keywords}
            package = kwargs["package"]
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
    assert set(calls) == {"stylizer", "vmc_bridge", "synthetic_performer"}
    for executable, kwargs in calls.items():
        assert re.search(rf"'{executable} = motion_style_ros\.nodes\.{executable}:main'", setup)
        assert ast.literal_eval(kwargs["name"]) == executable
    assert any(isinstance(n, ast.FunctionDef) and n.name == "generate_launch_description"
               for n in tree.body)


def test_launch_sets_only_declared_parameters():
    tree = ast.parse(LAUNCH.read_text())
    arguments = next(n.value for n in tree.body if isinstance(n, ast.Assign)
                     and getattr(n.targets[0], "id", "") == "STYLIZER_ARGUMENTS")
    set_by_launch = {ast.literal_eval(v.elts[0]) for v in arguments.values}
    assert set_by_launch <= declared("stylizer")
    performer = node_calls(tree)["synthetic_performer"]["parameters"].elts[0]
    assert {ast.literal_eval(k) for k in performer.keys} <= declared("synthetic_performer")


def test_params_files_hold_declared_parameters():
    assert yaml_parameters(ROOT / "config" / "stylizer.yaml", "stylizer") == declared("stylizer")
    assert yaml_parameters(ROOT / "config" / "vmc_bridge.yaml", "vmc_bridge") <= declared("vmc_bridge")
    text = LAUNCH.read_text()
    for name in ("stylizer.yaml", "vmc_bridge.yaml"):
        assert f"[share, 'config', '{name}']" in text
