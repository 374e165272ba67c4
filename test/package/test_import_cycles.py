"""No import cycles inside robot_calib (one home per thing, layers that point down).

Every module's imports, read with `ast`: relative ones resolved, those inside functions and
under `if TYPE_CHECKING:` counted too (a lazy import that closes a loop is still a cycle,
only hidden). `from P import name` is an edge to the module P.name when that is a module,
else to P. Imports by computed name (`importlib.import_module`, the effect, export and bag
registries) are not followed. A package's `__init__` is not implied by importing one of
its modules (else every package whose `__init__` imports its own modules would be a cycle).
"""

from __future__ import annotations

import ast
from pathlib import Path

import robot_calib

PACKAGE = Path(robot_calib.__file__).parent


def import_graph(package: Path) -> dict[str, set[str]]:
    """{module: the modules of the same package it imports}, for every .py under `package`."""
    files = {}
    for path in package.rglob("*.py"):
        parts = path.relative_to(package.parent).with_suffix("").parts
        files[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph: dict[str, set[str]] = {}
    for name, path in files.items():
        here = name if path.name == "__init__.py" else name.rpartition(".")[0]
        graph[name] = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = here.rsplit(".", node.level - 1)[0] if node.level else ""
                module = ".".join(p for p in (base, node.module or "") if p)
                targets = [
                    f"{module}.{a.name}" if f"{module}.{a.name}" in files else module
                    for a in node.names
                ]
            else:
                continue
            graph[name] |= {t for t in targets if t in files and t != name}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of `graph` as [a, b, ..., a], or None (depth-first, three colours)."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(module: str) -> list[str] | None:
        state[module] = 1
        path.append(module)
        for target in sorted(graph[module]):
            if state.get(target) == 1:
                return path[path.index(target) :] + [target]
            if target not in state and (found := visit(target)):
                return found
        state[module] = 2
        path.pop()
        return None

    return next((c for m in sorted(graph) if m not in state and (c := visit(m))), None)


def test_robot_calib_has_no_import_cycle() -> None:
    graph = import_graph(PACKAGE)
    assert len(graph) > 100 and "robot_calib.identify.calibration" in graph
    assert "robot_calib.identify.calibration" in graph["robot_calib.identify.calibrate"]
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_the_walker_finds_a_cycle_closed_by_a_lazy_relative_import(tmp_path: Path) -> None:
    """A package whose loop closes only inside a function, through a relative import."""
    package = tmp_path / "pkg"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "sub" / "__init__.py").write_text("")
    (package / "a.py").write_text("from pkg.sub import b\n")
    (package / "sub" / "b.py").write_text("from . import c\nimport os\n")
    (package / "sub" / "c.py").write_text("def f():\n    from ..a import x\n")
    (package / "d.py").write_text("from .sub.c import f\n")  # no cycle of its own
    graph = import_graph(package)
    assert graph["pkg.d"] == {"pkg.sub.c"} and graph["pkg.sub.c"] == {"pkg.a"}
    assert find_cycle(graph) == ["pkg.a", "pkg.sub.b", "pkg.sub.c", "pkg.a"]
    (package / "sub" / "c.py").write_text("def f():\n    pass\n")
    assert find_cycle(import_graph(package)) is None


FRONT_ENDS = ("robot_calib.cli", "robot_calib.nodes", "robot_calib.api")
# the science and the formats: pure functions of their inputs, run on whatever runner the
# caller installed (robot_calib.parallel), never a flow's or the process machinery's
SCIENCE = (
    "robot_calib.kinematics",
    "robot_calib.effects",
    "robot_calib.model",
    "robot_calib.poses",
    "robot_calib.measurements",
    "robot_calib.identify",
    "robot_calib.diagnosis",
    "robot_calib.compensation",
    "robot_calib.export",
    "robot_calib.sim",
    "robot_calib.plan",
    "robot_calib.bag",
)


def within(module: str, packages: tuple[str, ...]) -> bool:
    return any(module == p or module.startswith(p + ".") for p in packages)


def test_no_arrow_back_up() -> None:
    """Layers point down: nothing below the front ends (the command line, the nodes, the
    public API) imports one, and the science imports neither `flows/` nor the forked
    processes (`robot_calib.forked`), lazily or not."""
    graph = import_graph(PACKAGE)
    up = sorted(
        f"{module} -> {dep}"
        for module, deps in graph.items()
        for dep in deps
        if (
            not within(module, FRONT_ENDS)
            and module not in ("robot_calib", "robot_calib.__main__")
            and within(dep, FRONT_ENDS)
        )
        or (within(module, SCIENCE) and within(dep, ("robot_calib.flows", "robot_calib.forked")))
    )
    assert up == []
    assert within("robot_calib.identify.fit", SCIENCE) and not within("robot_calib.flows", SCIENCE)
