"""The files for a ROS install: launch/*.launch.py, config/robot_calib.yaml, rviz/robot_calib.rviz.

`launch` and `launch_ros` are not installable here (not in the Jazzy wheels), so the
launch files are checked as far as that allows: they compile and import only
robot_calib.nodes.launch_support, whose specs (the pure part: arguments, defaults, the
parameters of each node) are checked against the real nodes (instantiated in a private
rclpy context): every node of this package names a console script of setup.py and is given
only parameters it declares, with launch argument defaults of the declared types; every
launch argument used is declared; every package file referenced exists. The builder runs
against stand-ins of launch/launch_ros with the Jazzy constructors' signatures; where
`launch_ros` is importable (a ROS install), each description is also built for real. The
parameters YAML holds every node's declared parameters at their real defaults and loads
through rcl's own parser (`--params-file`). colcon installs these files:
test/package/test_package_layout.py.
"""

from __future__ import annotations

import ast
import inspect
import math
import subprocess
import sys
import types
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
from robot_calib.flows.bags import read_bags
from robot_calib.flows.calibrate import calibrate_recording
from robot_calib.kinematics.loader import load_robot
from robot_calib.messages import TRACKER_FRAME
from robot_calib.nodes import launch_support
from robot_calib.nodes.launch_support import (
    SIM_GRAPH,
    SPECS,
    FileText,
    FromArgument,
    LaunchSpec,
    ShareFile,
    Value,
    When,
)

ROOT = Path(__file__).resolve().parents[2]
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
            params = {
                **parameters_started(executable, context, tmp_path, mode="controller"),
                **params,
            }
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


def imports_of(path: Path) -> list[tuple[str, list[str]]]:
    """Every import of a file, anywhere in it: (module, names)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and node.module:
            out.append((node.module, [a.name for a in node.names]))
        elif isinstance(node, ast.Import):
            out += [(a.name, []) for a in node.names]
    return out


def test_launch_files_import_only_the_helper_and_start_its_spec() -> None:
    """Each launch file compiles, imports robot_calib.nodes.launch_support and nothing else
    (not launch, not launch_ros: the helper does, when the description is built) and builds
    the helper's spec of its own name."""
    assert (
        {p.name for p in LAUNCH_FILES}
        == set(SPECS)
        == {"sim_graph.launch.py", "capture.launch.py", "calibrator.launch.py"}
    )
    for path in LAUNCH_FILES:
        code = compile(path.read_text(), str(path), "exec")
        assert "generate_launch_description" in code.co_names
        ((module, names),) = imports_of(path)
        assert module == "robot_calib.nodes.launch_support", path.name
        (spec,) = [n for n in names if n != "launch_description"]
        assert getattr(launch_support, spec) is SPECS[path.name], path.name
        assert f"return launch_description({spec})" in path.read_text(), path.name


def test_importing_the_helper_needs_no_launch_package() -> None:
    probe = (
        "import sys, robot_calib.nodes.launch_support\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('launch', 'launch_ros')))"
    )
    run = subprocess.run(
        [sys.executable, "-c", probe],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT / "test",
    )
    assert run.stdout.strip() == "[]"


def typed_default(value: Value, spec: LaunchSpec, when: When | None) -> tuple[Any, str]:
    """The value a parameter gets by default and how: a constant, or a launch argument's
    default as launch_ros types it (yaml.safe_load of the text; `text`: the text itself).
    None where no default reaches the node (a required argument, or one the node's
    condition requires to be given)."""
    if not isinstance(value, FromArgument):
        return value, "constant"
    arguments = {a.name: a.default for a in spec.all_arguments}
    default = arguments[value.argument]
    if default is None or (when == When(value.argument, "given")):
        return None, f"argument {value.argument} (given)"
    assert isinstance(default, str)
    if value.text:
        return default, f"argument {value.argument} as text"
    loaded = yaml.safe_load(default)
    # launch_ros (evaluate_parameter_dict) refuses None ('') and empty or mixed lists
    assert isinstance(loaded, bool | int | float | str) or (
        isinstance(loaded, list) and loaded and len({type(x) for x in loaded}) == 1
    ), f"{spec.name}: launch_ros refuses {value.argument}'s default {default!r}"
    return loaded, f"argument {value.argument}"


def test_launch_specs_start_our_executables_with_declared_parameters(
    defaults: dict[str, dict[str, Any]],
) -> None:
    """The helper's pure part against the real nodes: every node of this package is a
    console script of setup.py, every parameter it is given is one the node declares, of
    the declared type at the launch argument's default; every argument used is declared
    once; every package file named exists."""
    nodes = setup_nodes()
    started: set[str] = set()
    for spec in SPECS.values():
        names = [a.name for a in spec.all_arguments]
        assert len(names) == len(set(names)) and names[0] == "params_file", spec.name
        for argument in spec.all_arguments:
            if isinstance(argument.default, ShareFile):
                assert (ROOT / argument.default.folder / argument.default.name).is_file()
        for node in spec.nodes:
            used = [v.argument for v in node.parameters.values() if isinstance(v, FromArgument)]
            used += [node.when.argument] if node.when else []
            assert set(used) <= set(names), f"{spec.name}: {set(used) - set(names)} undeclared"
            for item in node.arguments:
                if isinstance(item, ShareFile):
                    assert (ROOT / item.folder / item.name).is_file(), item
            if node.package == "rviz2":
                assert node.executable == "rviz2" and not node.parameters
                assert ShareFile("rviz", RVIZ.name) in node.arguments, "rviz2 without our config"
                continue
            if node.package == "robot_state_publisher":  # on the URDF file the calibrator
                assert node.executable == "robot_state_publisher"  # writes into and updates
                assert node.parameters == {"robot_description": FileText("urdf")}
                assert node.when is not None and node.when.argument == "urdf"
                continue
            assert node.package == PACKAGE, f"{spec.name}: unknown package {node.package}"
            assert node.executable in nodes, f"{spec.name}: {node.executable} not in setup.py"
            started.add(node.executable)
            declared = defaults[node.executable]
            for name, value in node.parameters.items():
                assert name in declared, f"{spec.name}: {node.executable} declares no {name!r}"
                got, how = typed_default(value, spec, node.when)
                if got is None:
                    continue
                want = type(declared[name])
                ok = isinstance(got, want) and not (want is int and isinstance(got, bool))
                if want is float:  # declare() takes an int for a float parameter
                    ok = isinstance(got, int | float) and not isinstance(got, bool)
                assert ok, f"{spec.name}: {node.executable}.{name} = {got!r} ({how}), want {want}"
    assert started == {"sim_robot", "sim_tracker", "recorder", "capture", "calibrator"}


def test_sim_graph_launch_waits_as_the_recipe_does() -> None:
    """sim_robot waits for its two readers, sim_tracker for the recorder."""
    arguments = {a.name: a.default for a in SIM_GRAPH.all_arguments}
    assert arguments["wait_for_subscribers"] == "2"
    nodes = {n.executable: n for n in SIM_GRAPH.nodes}
    robot, tracker = nodes["sim_robot"].parameters, nodes["sim_tracker"].parameters
    assert robot["wait_for_subscribers"] == FromArgument("wait_for_subscribers")
    assert tracker["wait_for_subscribers"] == 1
    assert robot["world"] == tracker["world"] == FromArgument("world", text=True)  # one world
    assert nodes["sim_robot"].shutdown_after_s == 1.0  # the last points reach the bag


# Stand-ins for the parts of launch and launch_ros the helper uses, with the constructors'
# signatures of ROS 2 Jazzy (launch 3.4, launch_ros 0.26): a wrong keyword fails as it would
# there. Node's **kwargs go to launch.actions.ExecuteProcess / Action.
EXECUTE_PROCESS_KEYWORDS = {
    *("output", "condition", "respawn", "respawn_delay", "emulate_tty", "sigterm_timeout"),
    *("sigkill_timeout", "on_exit", "cwd", "env"),
}


def _signatures() -> dict[str, dict[str, Any]]:
    def launch_description(initial_entities=None, *, deprecated_reason=None): ...
    def declare_launch_argument(
        name, *, default_value=None, description=None, choices=None, **kwargs
    ): ...
    def emit_event(*, event, **kwargs): ...
    def register_event_handler(event_handler, **kwargs): ...
    def timer_action(*, period, actions, cancel_on_shutdown=True, **kwargs): ...
    def if_condition(predicate_expression): ...
    def on_process_exit(*, target_action=None, on_exit, **kwargs): ...
    def shutdown(*, reason="reason not given", **kwargs): ...
    def equals(left, right): ...
    def launch_configuration(variable_name, *, default=None): ...
    def path_join(substitutions): ...
    def node(
        *,
        executable,
        package=None,
        name=None,
        namespace=None,
        exec_name=None,
        parameters=None,
        remappings=None,
        ros_arguments=None,
        arguments=None,
        **kwargs,
    ): ...
    def parameter_value(value, *, value_type=None): ...
    def command(command, *, on_stderr="fail"): ...
    def find_package_share(package): ...

    return {
        "launch": {"LaunchDescription": launch_description},
        "launch.actions": {
            "DeclareLaunchArgument": declare_launch_argument,
            "EmitEvent": emit_event,
            "RegisterEventHandler": register_event_handler,
            "TimerAction": timer_action,
        },
        "launch.conditions": {"IfCondition": if_condition},
        "launch.event_handlers": {"OnProcessExit": on_process_exit},
        "launch.events": {"Shutdown": shutdown},
        "launch.substitutions": {
            "Command": command,
            "EqualsSubstitution": equals,
            "NotEqualsSubstitution": equals,
            "LaunchConfiguration": launch_configuration,
            "PathJoinSubstitution": path_join,
        },
        "launch_ros.actions": {"Node": node},
        "launch_ros.parameter_descriptions": {"ParameterValue": parameter_value},
        "launch_ros.substitutions": {"FindPackageShare": find_package_share},
    }


class StandIn:
    """An object of a stand-in class: its class name and the arguments it was given."""

    def __init__(self, kind: str, given: dict[str, Any]) -> None:
        self.kind, self.given = kind, given


def stand_in_modules() -> dict[str, types.ModuleType]:
    modules = {}
    for module_name, classes in _signatures().items():
        module = types.ModuleType(module_name)
        for class_name, function in classes.items():
            signature = inspect.signature(function)

            def make(*args: Any, _s: Any = signature, _n: str = class_name, **kw: Any) -> StandIn:
                bound = _s.bind(*args, **kw)  # TypeError as the real constructor
                given = {k: v for k, v in bound.arguments.items() if k != "kwargs"}
                given.update(bound.arguments.get("kwargs", {}))
                return StandIn(_n, given)

            setattr(module, class_name, make)
        modules[module_name] = module
    return modules


def render(x: Any) -> Any:  # noqa: ANN401 - any part of a description
    """A description as plain data: (class, {argument: value}) for every launch object."""
    if isinstance(x, StandIn):
        return (x.kind, {k: render(v) for k, v in x.given.items()})
    if isinstance(x, list | tuple):
        return [render(v) for v in x]
    if isinstance(x, dict):
        return {k: render(v) for k, v in x.items()}
    return x


def built_with_stand_ins(path: Path, monkeypatch: pytest.MonkeyPatch) -> Any:  # noqa: ANN401
    import runpy

    for name, module in stand_in_modules().items():
        monkeypatch.setitem(sys.modules, name, module)
    return runpy.run_path(str(path))["generate_launch_description"]()


def test_launch_descriptions_build_with_stand_ins_of_the_jazzy_api(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The builder against constructors of launch/launch_ros's signatures: every launch
    file builds; our nodes load the YAML first, then their parameters; string parameters as
    text; the shutdown after sim_robot (1 s later) and capture (at once)."""
    config = (
        "PathJoinSubstitution",
        {
            "substitutions": [
                ("FindPackageShare", {"package": PACKAGE}),
                "config",
                "robot_calib.yaml",
            ]
        },
    )
    text = {}
    for path in LAUNCH_FILES:
        (kind, given) = render(built_with_stand_ins(path, monkeypatch))
        assert kind == "LaunchDescription", path.name
        entities = given["initial_entities"]
        first = entities[0]
        assert first == (
            "DeclareLaunchArgument",
            {
                "name": "params_file",
                "default_value": config,
                "description": "parameters YAML of the nodes (the arguments below win)",
            },
        )
        for kind, args in entities:
            if kind == "Node":
                assert set(args) - {"package", "executable", "parameters", "arguments"} <= (
                    EXECUTE_PROCESS_KEYWORDS
                ), args
                assert args["output"] == "screen"
                if args["package"] == PACKAGE:
                    yaml_file, own = args["parameters"]
                    assert yaml_file == ("LaunchConfiguration", {"variable_name": "params_file"})
                    assert isinstance(own, dict) and own, args
        text[path.name] = repr(entities)
    assert (
        "('ParameterValue', {'value': ('LaunchConfiguration', {'variable_name': 'plan'}), "
        "'value_type': <class 'str'>})" in text["sim_graph.launch.py"]
    )
    assert "'period': 1.0" in text["sim_graph.launch.py"]
    assert "'reason': 'plan done'" in text["sim_graph.launch.py"]
    assert "'reason': 'capture ended'" in text["capture.launch.py"]
    assert "TimerAction" not in text["capture.launch.py"]
    calibrator = text["calibrator.launch.py"]  # bag mode if bags given, else live mode
    assert (
        "('NotEqualsSubstitution', {'left': ('LaunchConfiguration', {'variable_name': "
        "'bags'}), 'right': ''})" in calibrator
    )
    assert (
        "('EqualsSubstitution', {'left': ('LaunchConfiguration', {'variable_name': "
        "'bags'}), 'right': ''})" in calibrator
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
    """The packages the launch files and their helper import (launch, launch_ros), `ros2
    launch` itself and rviz2 (calibrator.launch.py rviz:=true) are exec_depends."""
    from test_package_layout import package_xml_depends

    depends = package_xml_depends()
    files = [*LAUNCH_FILES, Path(launch_support.__file__)]
    tops = {module.split(".")[0] for path in files for module, _ in imports_of(path)}
    tops -= {PACKAGE, *sys.stdlib_module_names}
    assert tops == {"launch", "launch_ros"}
    assert tops | {"ros2launch", "rviz2"} <= depends
