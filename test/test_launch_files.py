"""The files for a ROS install: launch/*.launch.py, config/robot_calib.yaml, rviz/robot_calib.rviz.

`launch` and `launch_ros` are not installable here (not in the Jazzy wheels), so the
launch files are checked as far as that allows: they compile; parsed with `ast`, every
Node of this package names a console script of setup.py and passes only parameters that
the real node declares (the nodes are instantiated in a private rclpy context), with launch
argument defaults of the declared types; every launch configuration used is declared;
every package file referenced exists. Where `launch` is importable (a ROS install), each
description is also built. The parameters YAML holds every node's declared parameters at
their real defaults and loads through rcl's own parser (`--params-file`). colcon installs
these files: test/test_package_layout.py.
"""

from __future__ import annotations

import ast
import math
import re
from pathlib import Path
from typing import Any

import pytest
import rclpy
import yaml
from rcl_interfaces.msg import ParameterType
from rclpy.context import Context
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node

from robot_calib.errors import InputError
from robot_calib.kinematics.loader import load_robot
from robot_calib.messages import TRACKER_FRAME
from robot_calib.pipeline import calibrate_recording, read_bags

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "robot_calib"
LAUNCH_FILES = sorted((ROOT / "launch").glob("*.launch.py"))
PARAMS_YAML = ROOT / "config" / "robot_calib.yaml"
RVIZ = ROOT / "rviz" / "robot_calib.rviz"
SAMPLE = ROOT / "bags" / "paper_test3.mcap"
# Parameters a node refuses to start without (their declared default is '').
REQUIRED = {"recorder": "output", "replay": "bag", "compensator": "params", "capture": "output"}
# Parameters rclpy declares on every node (not ours to list in the YAML).
RCLPY_PARAMETERS = {"use_sim_time", "start_type_description_service"}
# The parameter types a node can declare (robot_calib/nodes/_common.py declare()).
PY_TYPES = {
    ParameterType.PARAMETER_STRING: str,
    ParameterType.PARAMETER_INTEGER: int,
    ParameterType.PARAMETER_DOUBLE: float,
    ParameterType.PARAMETER_BOOL: bool,
    ParameterType.PARAMETER_STRING_ARRAY: list,
}


def setup_nodes() -> list[str]:
    """NODES of setup.py (its console scripts besides robot-calib), read with ast."""
    tree = ast.parse((ROOT / "setup.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and [getattr(t, "id", "") for t in node.targets] == [
            "NODES"
        ]:
            return list(ast.literal_eval(node.value))
    raise AssertionError("setup.py has no NODES")


def node_class(executable: str) -> type[Node]:
    """The Node class a console script runs (robot_calib.nodes.<executable>)."""
    import importlib

    module = importlib.import_module(f"robot_calib.nodes.{executable}")
    (cls,) = [
        c
        for c in vars(module).values()
        if isinstance(c, type) and issubclass(c, Node) and c.__module__ == module.__name__
    ]
    return cls


def params_file(tmp_path: Path) -> Path:
    """A PARAMS.json for the compensator (the nominal model of the sample bag: fast)."""
    path = tmp_path / "params.json"
    if not path.exists():
        from robot_calib.identify.params_file import write_json_atomic

        robot = load_robot("kr5_sixx_r650")
        recording = read_bags([SAMPLE], robot, 0.05, lambda _line: None)
        cal = calibrate_recording(recording, robot, "nominal", 1, log=None)
        write_json_atomic(cal.to_dict(recording), path)
    return path


def required_values(executable: str, tmp_path: Path) -> dict[str, str]:
    """Values that let the node start: a new bag path, the sample bag, a PARAMS.json."""
    values = {
        "recorder": str(tmp_path / "recorded.mcap"),
        "replay": str(SAMPLE),
        "compensator": str(params_file(tmp_path)) if executable == "compensator" else "",
        "capture": str(tmp_path / "campaign.mcap"),
    }
    return {REQUIRED[executable]: values[executable]} if executable in REQUIRED else {}


def parameters_of(node: Node) -> dict[str, Any]:
    """A node's declared parameters (not rclpy's own) and their values ([] for an unset
    string array: declare()'s empty-list default)."""
    names = [n for n in node.list_parameters([], 0).names if n not in RCLPY_PARAMETERS]
    out: dict[str, Any] = {}
    for name, descriptor in zip(names, node.describe_parameters(names)):
        try:
            value = node.get_parameter(name).value
        except ParameterUninitializedException:
            value = []
        if descriptor.type != ParameterType.PARAMETER_NOT_SET:  # floats: dynamic typing
            assert isinstance(value, PY_TYPES[descriptor.type]), name
        out[name] = list(value) if isinstance(value, list | tuple) else value
    return out


def parameters_started(
    executable: str, context: Context, tmp_path: Path, **values: Any
) -> dict[str, Any]:
    """The declared parameters of the real node of `executable`, started in `context` with
    the required and given values (then destroyed)."""
    from rclpy.parameter import Parameter

    given = {**required_values(executable, tmp_path), **values}
    overrides = [Parameter(k, value=v) for k, v in given.items()]
    node = node_class(executable)(context=context, parameter_overrides=overrides)
    try:
        return parameters_of(node)
    finally:
        node.destroy_node()


def declared_defaults(context: Context, tmp_path: Path) -> dict[str, dict[str, Any]]:
    """Every node of setup.py: its declared parameters at their defaults (the required ones
    at ''). sim_robot's controller-mode parameters come from a second instance."""
    out: dict[str, dict[str, Any]] = {}
    for executable in setup_nodes():
        params = parameters_started(executable, context, tmp_path)
        if executable == "sim_robot":  # plan mode's values first
            params = {**parameters_started(executable, context, tmp_path, mode="controller"),
                      **params}  # fmt: skip
        for name in required_values(executable, tmp_path):
            params[name] = ""  # refused when not given (test below)
        out[executable] = params
    return out


@pytest.fixture(scope="module")
def defaults(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict[str, Any]]:
    context = Context()
    rclpy.init(context=context)
    try:
        return declared_defaults(context, tmp_path_factory.mktemp("nodes"))
    finally:
        rclpy.try_shutdown(context=context)


def same(a: Any, b: Any) -> bool:  # noqa: ANN401 - parameter values
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a):
        return math.isnan(b)
    return type(a) is type(b) and a == b


# --- the parameters YAML --------------------------------------------------------------------


def test_params_yaml_holds_every_node_parameter_at_its_declared_default(
    defaults: dict[str, dict[str, Any]],
) -> None:
    document = yaml.safe_load(PARAMS_YAML.read_text())
    assert sorted(document) == sorted(setup_nodes())
    for executable, section in document.items():
        assert list(section) == ["ros__parameters"], executable
        given = section["ros__parameters"]
        declared = defaults[executable]
        unknown = sorted(set(given) - set(declared))
        assert not unknown, f"{executable}: {unknown} are not declared by the node"
        missing = sorted(set(declared) - set(given))
        assert not missing, f"{executable}: {missing} missing from {PARAMS_YAML.name}"
        for name, value in given.items():
            assert same(value, declared[name]), (
                f"{executable}.{name}: {value!r} in the YAML, the node's default is "
                f"{declared[name]!r}"
            )


def test_params_yaml_loads_through_rcl_and_changes_no_default(
    defaults: dict[str, dict[str, Any]], tmp_path: Path
) -> None:
    """`--ros-args --params-file config/robot_calib.yaml`, parsed by rcl as `ros2 run` and
    launch do: every node starts with it and keeps its defaults."""
    context = Context()
    rclpy.init(context=context, args=["--ros-args", "--params-file", str(PARAMS_YAML)])
    try:
        for executable in setup_nodes():
            loaded = parameters_started(executable, context, tmp_path)
            for name, value in loaded.items():
                if name != REQUIRED.get(executable):
                    assert same(value, defaults[executable][name]), f"{executable}.{name}"
    finally:
        rclpy.try_shutdown(context=context)


def test_required_parameters_are_refused_empty(context: Context, tmp_path: Path) -> None:
    """The YAML's '' for `output`, `bag`, `params` is the nodes' real default: refused."""
    from rclpy.parameter import Parameter

    for executable, name in REQUIRED.items():
        with pytest.raises(InputError, match=name):
            node_class(executable)(
                context=context, parameter_overrides=[Parameter(name, value="")]
            )


# --- the launch files ----------------------------------------------------------------------


def call_name(call: ast.Call) -> str:
    return getattr(call.func, "id", getattr(call.func, "attr", ""))


def keyword(call: ast.Call, name: str) -> ast.expr | None:
    return next((k.value for k in call.keywords if k.arg == name), None)


def first_argument(call: ast.Call) -> str:
    arg = call.args[0] if call.args else keyword(call, "name")
    assert isinstance(arg, ast.Constant) and isinstance(arg.value, str), ast.unparse(call)
    return arg.value


class LaunchFile:
    """What a launch description declares and starts, read with ast."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.tree = ast.parse(path.read_text(), filename=str(path))
        calls = [n for n in ast.walk(self.tree) if isinstance(n, ast.Call)]
        self.arguments: dict[str, str | None] = {}  # launch argument -> default value
        for call in calls:
            if call_name(call) == "DeclareLaunchArgument":
                default = keyword(call, "default_value")
                value = default.value if isinstance(default, ast.Constant) else None
                self.arguments[first_argument(call)] = value
        self.configurations = {
            first_argument(c) for c in calls if call_name(c) == "LaunchConfiguration"
        }
        self.nodes = [c for c in calls if call_name(c) == "Node"]
        # simple assignments (PACKAGE = "robot_calib", params_file = LaunchConfiguration(...))
        self.names = {
            a.targets[0].id: a.value
            for a in ast.walk(self.tree)
            if isinstance(a, ast.Assign) and len(a.targets) == 1
            and isinstance(a.targets[0], ast.Name)
        }  # fmt: skip
        self.share_files = [
            [a.value for a in c.args[0].elts[1:] if isinstance(a, ast.Constant)]
            for c in calls
            if call_name(c) == "PathJoinSubstitution"
            and isinstance(c.args[0], ast.List)
            and "FindPackageShare" in ast.unparse(c.args[0].elts[0])
        ]

    def resolve(self, expr: ast.expr | None) -> ast.expr:
        """`expr`, a name replaced by what it was assigned."""
        assert expr is not None
        while isinstance(expr, ast.Name) and expr.id in self.names:
            expr = self.names[expr.id]
        return expr

    def constant(self, call: ast.Call, name: str) -> str:
        value = self.resolve(keyword(call, name))
        assert isinstance(value, ast.Constant), f"{self.path.name}: {ast.unparse(call)}"
        return str(value.value)

    def nonempty_arguments(self, call: ast.Call) -> set[str]:
        """Launch arguments the Node's condition requires to be non-empty
        (`condition=IfCondition(NotEqualsSubstitution(LaunchConfiguration(x), ''))`)."""
        condition = keyword(call, "condition")
        if not (isinstance(condition, ast.Call) and call_name(condition) == "IfCondition"):
            return set()
        test = condition.args[0]
        if not (isinstance(test, ast.Call) and call_name(test) == "NotEqualsSubstitution"):
            return set()
        left, right = (self.resolve(a) for a in test.args)
        match = re.fullmatch(ARGUMENT, ast.unparse(left))
        return {match.group(1)} if match and ast.unparse(right) == "''" else set()

    def parameters(self, call: ast.Call) -> tuple[ast.expr, dict[str, ast.expr]]:
        """A Node's `parameters=[FILE, {name: value, **more}, ...]`: FILE and the dicts'
        entries (names resolved)."""
        params = self.resolve(keyword(call, "parameters"))
        assert isinstance(params, ast.List), f"{self.path.name}: {ast.unparse(call)}"
        entries: dict[str, ast.expr] = {}

        def add(d: ast.expr) -> None:
            d = self.resolve(d)
            assert isinstance(d, ast.Dict), f"{self.path.name}: {ast.unparse(d)}"
            for key, value in zip(d.keys, d.values):
                if key is None:  # **more
                    add(value)
                else:
                    assert isinstance(key, ast.Constant) and isinstance(key.value, str)
                    entries[key.value] = self.resolve(value)

        for entry in params.elts[1:]:
            add(entry)
        return self.resolve(params.elts[0]), entries


ARGUMENT = r"LaunchConfiguration\('(\w+)'\)"  # a launch argument's value, as ast unparses it


def typed_value(value: ast.expr, launch: LaunchFile, nonempty: set[str]) -> tuple[Any, str]:
    """The value a parameter gets and how: a constant, or a launch argument's default as
    launch_ros types it (yaml.safe_load of the text; ParameterValue(value_type=str): text).
    None where there is no default to check (a required argument, or one in `nonempty`: the
    Node's condition keeps its default out)."""
    if isinstance(value, ast.Constant):
        return value.value, "constant"
    text = ast.unparse(value)
    match = re.fullmatch(ARGUMENT, text)
    forced = re.fullmatch(rf"ParameterValue\({ARGUMENT}, value_type=str\)", text)
    if forced:
        return launch.arguments[forced.group(1)], f"argument {forced.group(1)} as text"
    assert match, f"{launch.path.name}: parameter value {text} is not checked by this test"
    default = launch.arguments[match.group(1)]
    if default is None or match.group(1) in nonempty:  # no default reaches the node
        return None, f"argument {match.group(1)} (given)"
    loaded = yaml.safe_load(default)
    # launch_ros (evaluate_parameter_dict) refuses None ('') and empty or mixed lists
    assert isinstance(loaded, bool | int | float | str) or (
        isinstance(loaded, list) and loaded and len({type(x) for x in loaded}) == 1
    ), f"{launch.path.name}: launch_ros refuses {match.group(1)}'s default {default!r}"
    return loaded, f"argument {match.group(1)}"


def test_launch_files_exist_and_compile() -> None:
    names = {p.name for p in LAUNCH_FILES}
    assert names == {"sim_graph.launch.py", "capture.launch.py", "calibrator.launch.py"}
    for path in LAUNCH_FILES:
        code = compile(path.read_text(), str(path), "exec")
        assert "generate_launch_description" in code.co_names


def test_launch_files_start_our_executables_with_declared_parameters(
    defaults: dict[str, dict[str, Any]],
) -> None:
    nodes = setup_nodes()
    started: set[str] = set()
    for path in LAUNCH_FILES:
        launch = LaunchFile(path)
        assert launch.nodes, path.name
        undeclared = launch.configurations - set(launch.arguments)
        assert not undeclared, f"{path.name}: launch configurations {undeclared} not declared"
        for parts in launch.share_files:  # FindPackageShare('robot_calib') / DIR / FILE
            assert (ROOT.joinpath(*parts)).is_file(), f"{path.name}: no {'/'.join(parts)}"
        for call in launch.nodes:
            package = launch.constant(call, "package")
            executable = launch.constant(call, "executable")
            if package == "rviz2":
                assert executable == "rviz2"
                assert ["rviz", RVIZ.name] in launch.share_files, "rviz2 without our config"
                continue
            assert package == PACKAGE, f"{path.name}: unknown package {package}"
            assert executable in nodes, f"{path.name}: {executable} is not in setup.py NODES"
            assert keyword(call, "name") is None  # the YAML's sections are the default names
            started.add(executable)
            first, entries = launch.parameters(call)
            # the YAML first, then the launch's own values (they win)
            assert ast.unparse(first) == "LaunchConfiguration('params_file')", path.name
            for name, value in entries.items():
                declared = defaults[executable]
                assert name in declared, f"{path.name}: {executable} declares no {name!r}"
                got, how = typed_value(value, launch, launch.nonempty_arguments(call))
                if got is None:
                    continue
                want = type(declared[name])
                ok = isinstance(got, want) and not (want is int and isinstance(got, bool))
                if want is float:  # declare() takes an int for a float parameter
                    ok = isinstance(got, int | float) and not isinstance(got, bool)
                assert ok, f"{path.name}: {executable}.{name} = {got!r} ({how}), want {want}"
    assert started == {"sim_robot", "sim_tracker", "recorder", "capture", "calibrator"}


def test_sim_graph_launch_waits_as_the_recipe_does() -> None:
    """sim_robot waits for its two readers, sim_tracker for the recorder (issue 16)."""
    launch = LaunchFile(ROOT / "launch" / "sim_graph.launch.py")
    assert launch.arguments["wait_for_subscribers"] == "2"
    text = {launch.constant(c, "executable"): ast.unparse(c) for c in launch.nodes}
    assert (
        "'wait_for_subscribers': LaunchConfiguration('wait_for_subscribers')" in text["sim_robot"]
    )
    assert "'wait_for_subscribers': 1" in text["sim_tracker"]
    for executable in ("sim_robot", "sim_tracker"):  # one world for both
        assert (
            "'world': ParameterValue(LaunchConfiguration('world'), value_type=str)"
            in text[executable]
        )


def test_launch_descriptions_build_where_launch_is_installed() -> None:
    pytest.importorskip(
        "launch_ros", reason="launch_ros is not installable here (not in the Jazzy wheels)"
    )
    import runpy

    for path in LAUNCH_FILES:
        description = runpy.run_path(str(path))["generate_launch_description"]()
        assert description.entities, path.name


# --- the RViz config -----------------------------------------------------------------------


def test_rviz_config_shows_what_the_calibrator_publishes(context: Context) -> None:
    from robot_calib.nodes.calibrator import LATCHED, CalibratorNode

    config = yaml.safe_load(RVIZ.read_text())
    manager = config["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == TRACKER_FRAME  # the markers' frame
    displays = {d["Class"]: d for d in manager["Displays"]}
    markers = displays["rviz_default_plugins/MarkerArray"]
    assert set(markers["Namespaces"]) == {"axes", "circles", "measured", "residuals"}
    calibrator = CalibratorNode(context=context)
    try:
        published = {p.topic_name: p for p in calibrator.publishers}
    finally:
        calibrator.destroy_node()
    topic = markers["Topic"]
    publisher = published[topic["Value"]]
    assert publisher.msg_type.__name__ == "MarkerArray"
    assert publisher.qos_profile.durability == LATCHED.durability
    assert topic["Durability Policy"] == "Transient Local"  # else RViz misses the result
    assert topic["Reliability Policy"] == "Reliable"
    point = displays["rviz_default_plugins/PointStamped"]["Topic"]
    assert point["Value"] == "/laser_tracker/point"


def test_package_xml_declares_what_the_launch_files_use() -> None:
    from test_package_layout import package_xml_depends

    depends = package_xml_depends()
    for path in LAUNCH_FILES:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                top = node.module.split(".")[0]
                assert top in depends, f"{path.name} imports {top}: not in package.xml"
    assert {"ros2launch", "rviz2"} <= depends  # `ros2 launch`; calibrator.launch.py rviz:=true
