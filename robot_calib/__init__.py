"""robot_calib: laser-tracker calibration of 6-axis robots and sim-to-real gap diagnosis.

Flow (one package per step): sim -> bag -> identify (CPA, geometric, effects) -> diagnose.
The core imports numpy/scipy only; ROS lives in `robot_calib.nodes`.
"""

import _signal  # the C module: `signal` takes ~10 ms to import (its enums)
import os
import sys
from collections.abc import Callable

__version__ = "0.1.0"

_API = "robot_calib.api"
#: the public Python API (robot_calib/api.py): each name and the module that defines it,
#: loaded on first use: `import robot_calib` stays light (no numpy or scipy until a
#: function is called)
_LAZY = {
    **dict.fromkeys(
        (
            "calibrate",
            "compensate",
            "compensate_program",
            "diagnose",
            "load_robot",
            "read_recording",
            "recording_from_arrays",
            "simulate",
        ),
        _API,
    ),
    "Calibration": "robot_calib.identify.calibration",
    "Diagnosis": "robot_calib.diagnosis.diagnosis",
    "ModelSpec": "robot_calib.identify.model_spec",
    "Recording": "robot_calib.measurements",
    "RobotCalibError": "robot_calib.errors",
    "InputError": "robot_calib.errors",
}
__all__ = [*_LAZY, "__version__"]


def lazy_exports(package: str, exports: dict[str, str]) -> Callable[[str], object]:
    """A package's module `__getattr__` (PEP 562): each name of `exports` imported from
    its module when first used, so that importing the package loads none of them."""

    def __getattr__(name: str) -> object:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        import importlib

        return getattr(importlib.import_module(module), name)

    return __getattr__


__getattr__ = lazy_exports(__name__, _LAZY)


def program_and_verb() -> str:
    """'robot-calib VERB' of this program's arguments (the verb: the first, unless an
    option): how its one-line messages begin before the verb's parser has run."""
    verb = next((a for a in sys.argv[1:2] if not a.startswith("-")), "")
    return f"robot-calib{' ' + verb if verb else ''}"


def _interrupted_while_starting(signum: int, _frame: object) -> None:
    """Ctrl-C / SIGTERM while `robot-calib` loads its modules (before `cli.main` installs its
    own handlers): nothing is written yet, so one line and exit 130 at once (was a
    KeyboardInterrupt traceback of whatever import was in progress)."""
    try:  # noqa: SIM105 - no contextlib import this early
        os.write(2, f"{program_and_verb()}: interrupted\n".encode())
    except OSError:  # stderr full or gone (`2>/dev/full`): the status still says it
        pass
    os._exit(130)


def _open_closed_descriptors() -> None:
    """Standard input, output and error that the caller closed (`>&-`, `2>&-`) become
    /dev/null before anything is imported or opened: no file the program opens gets
    descriptor 1 or 2 with the printed lines written into it (`cli.run` gives Python's
    missing sys.stdout / sys.stderr streams on them)."""
    for fd in (0, 1, 2):
        try:
            os.fstat(fd)
        except OSError:
            devnull = os.open(os.devnull, os.O_RDWR)
            if devnull != fd:
                os.dup2(devnull, fd)
                os.close(devnull)


def one_blas_thread() -> None:
    """One BLAS thread, unless the user chose (OPENBLAS_NUM_THREADS, OMP_NUM_THREADS,
    MKL_NUM_THREADS): the linear algebra here is many small solves (thousands of rows, tens
    of columns), fastest on one thread, and threaded OpenBLAS beside another busy process
    slowed them 50-fold (a diagnosis: 1.1 s vs 59 s on 2 cores). Effective only before numpy
    is imported: the programs' entries call it (`robot-calib`, the nodes), never a plain
    `import robot_calib` (a notebook's threads are its own business)."""
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")


#: the nodes' programs (setup.py's console scripts beside robot-calib, `ros2 run robot_calib
#: NODE`): started as these, or as `python -m robot_calib.nodes.NODE`, they get
#: `one_blas_thread` before any module imports numpy
NODE_PROGRAMS = (
    "sim_robot",
    "sim_tracker",
    "recorder",
    "replay",
    "calibrator",
    "compensator",
    "capture",
)


def _node_program() -> bool:
    """True when this process is one of the nodes' programs (NODE_PROGRAMS)."""
    argv = getattr(sys, "orig_argv", [])
    modules = [b for a, b in zip(argv, argv[1:]) if a == "-m"]
    program = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
    return program in NODE_PROGRAMS or any(m.startswith("robot_calib.nodes.") for m in modules)


def _console_program() -> bool:
    """True when the package is loaded by the `robot-calib` program or `python -m
    robot_calib` (not imported by a test, a node or another program)."""
    argv = getattr(sys, "orig_argv", [])
    as_module = any(a == "-m" and b == "robot_calib" for a, b in zip(argv, argv[1:]))
    program = sys.argv[0] if sys.argv and sys.argv[0] else ""
    return as_module or os.path.basename(program) == "robot-calib"


def _keep_freed_memory() -> None:
    """glibc's malloc (Linux): blocks up to 16 MB from the heap, and up to 64 MB of freed
    heap kept for reuse rather than handed back to the system, unless the user set these
    (MALLOC_MMAP_THRESHOLD_, MALLOC_TRIM_THRESHOLD_, MALLOC_TOP_PAD_ or glibc.malloc
    tunables). numpy's temporaries of a few MB (a Jacobian of 2773 poses: 3 MB) were
    otherwise mapped and unmapped at every step, each page faulted in and zeroed again: a
    diagnosis of 2773 poses took 212k page faults, 153-160k with this (0.3 s sooner).
    Memory: the heap's high-water mark stays resident (calibrate of 100k poses: peak RSS
    159 -> 181 MiB; diagnose of 100k: 522 MiB for the process tree). Nothing elsewhere
    (other systems, C libraries without mallopt)."""
    own = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_")
    if not sys.platform.startswith("linux") or any(name in os.environ for name in own):
        return
    if "glibc.malloc" in os.environ.get("GLIBC_TUNABLES", ""):
        return
    try:
        import ctypes

        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError, TypeError):
        return
    mallopt(-3, 16 << 20)  # M_MMAP_THRESHOLD
    mallopt(-1, 64 << 20)  # M_TRIM_THRESHOLD


if _node_program():
    one_blas_thread()

if _console_program():  # before the heavy imports of robot_calib.cli (numpy, ...: ~0.3 s)
    one_blas_thread()
    _open_closed_descriptors()
    # the handlers first: a Ctrl-C during any import after them (ctypes below) is one line
    if _signal.getsignal(_signal.SIGINT) is _signal.default_int_handler:
        _signal.signal(_signal.SIGINT, _interrupted_while_starting)
    if _signal.getsignal(_signal.SIGTERM) == _signal.SIG_DFL:
        _signal.signal(_signal.SIGTERM, _interrupted_while_starting)
    _keep_freed_memory()
