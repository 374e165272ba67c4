"""Work done aside by a forked child (`robot_calib.forked`): the same results as computed
here, whatever the child does (raises, dies, sends large results, is never forked because
another thread runs); a result is handed over as soon as it is sent; a value sent later
through a Mailbox; nothing left behind, not even when this process is killed. Each check
runs in a fresh interpreter, whose only thread is its own (the fork path; `pytest -n 0`
has a thread of pytest-rerunfailures, xdist workers have none)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ASIDE_CHECK = """
import os, signal, tempfile, threading, glob
import numpy as np
from robot_calib.forked import Aside

parent = os.getpid()
def big(k):  # 8 MB: far beyond a pipe's 64 KiB
    return np.random.default_rng(k).normal(size=(1_000_000,)), os.getpid()

def fails_in_a_child():
    if os.getpid() != parent:
        raise RuntimeError("only in the child")
    return "computed here"

def killed_in_a_child():
    if os.getpid() != parent:
        os.kill(os.getpid(), signal.SIGKILL)
    return "computed here"

folders = lambda: set(glob.glob(os.path.join(tempfile.gettempdir(), "robot_calib-aside-*")))
before = folders()
with Aside([(k, lambda k=k: big(k)) for k in range(3)]) as aside:
    assert aside.forked
    got = [aside.result(k) for k in (2, 0, 1)]  # any order
    assert aside.received == 3
for (values, pid), k in zip(got, (2, 0, 1)):
    assert np.array_equal(values, big(k)[0]) and pid != parent  # the child's
with Aside([("a", lambda: 1), ("bad", fails_in_a_child), ("c", lambda: 3)]) as aside:
    assert aside.result("a") == 1
    assert aside.result("bad") == "computed here"  # raised in the child: computed here
    assert aside.result("c") == 3  # after the failure: computed here
with Aside([("dies", killed_in_a_child), ("next", lambda: os.getpid())]) as aside:
    assert aside.result("dies") == "computed here"
    assert aside.result("next") == parent
try:
    with Aside([("slow", lambda: __import__("time").sleep(30))]) as aside:
        child = aside._child[0]
        raise KeyboardInterrupt  # Ctrl-C in the block: the child is killed at once
except KeyboardInterrupt:
    pass
try:
    os.kill(child, 0)
    raise SystemExit("the child still runs")
except ProcessLookupError:
    pass
stop = threading.Event()
other = threading.Thread(target=stop.wait)
other.start()
with Aside([("x", lambda: os.getpid())]) as aside:  # another thread runs: no fork
    assert not aside.forked and aside.result("x") == parent
stop.set()
other.join()
assert folders() == before, folders() - before  # every temporary folder removed
print("OK")
"""


HELPER_CHECK = """
import os, time, glob, tempfile, functools
import numpy as np
from robot_calib.forked import Aside, Helper

parent = os.getpid()
folders = lambda: set(glob.glob(os.path.join(tempfile.gettempdir(), "robot_calib-aside-*")))
before = folders()
PREPARED = []

def prepare():  # slow, as importing matplotlib is: paid once, the twin inherits it
    time.sleep(0.3)
    PREPARED.append(os.getpid())

def who(k):
    return k, os.getpid(), list(PREPARED)

first = Helper(prepare)
second = Helper(prepare)
third = Helper(prepare)
idle = Helper(prepare)
tasks = [(k, functools.partial(who, k)) for k in range(4)]  # picklable
with Aside(tasks, helper=first, split=2) as aside:
    assert aside.forked
    got = [aside.result(k) for k in (3, 0, 2, 1)]  # any order
    assert aside.received == 4
assert [k for k, _, _ in got] == [3, 0, 2, 1]
pids = {k: pid for k, pid, _ in got}
assert pids[0] == pids[1] != pids[2] == pids[3] and parent not in pids.values()  # helper, twin
assert all(prepared == [pids[0]] for _, _, prepared in got)  # prepared once, by the helper
with Aside([("n", functools.partial(np.arange, 3))], helper=second) as aside:
    assert aside.result("n").tolist() == [0, 1, 2] and aside.received == 1
with Aside([("lambda", lambda: os.getpid())], helper=third) as aside:  # not picklable:
    assert aside.result("lambda") != parent  # a child forked for it instead
with Aside([("again", functools.partial(int, 7))], helper=first) as aside:  # used: forks anew
    assert aside.result("again") == 7
idle.close()  # never given a batch: killed and reaped
try:
    with Aside([(k, functools.partial(time.sleep, 30)) for k in range(2)],
               helper=Helper(prepare), split=1) as aside:
        time.sleep(0.5)
        raise KeyboardInterrupt  # the helper and its twin killed at once
except KeyboardInterrupt:
    pass
assert folders() == before, folders() - before
print("OK")
"""


def _fresh(code: str) -> str:
    """`code` run by a fresh interpreter with a temporary directory of its own (the
    folders it finds there are its own, not those of tests running beside it)."""
    import os
    import tempfile

    with tempfile.TemporaryDirectory() as own:
        env = {**os.environ, "TMPDIR": own}
        done = subprocess.run(
            [sys.executable, "-c", code],
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
            env=env,
        )
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout.strip()


def test_results_aside_are_the_results_here_whatever_the_child_does() -> None:
    """Results larger than a pipe come through in any order; a task the child raised on
    or died in, and those after it, are computed here; Ctrl-C in the block kills the
    child; with another thread running nothing is forked; no temporary folder is left."""
    assert _fresh(ASIDE_CHECK) == "OK"


def test_a_helper_prepared_early_computes_the_batch_it_is_given_later() -> None:
    """`Helper`: its child prepares while the caller goes on, then computes the picklable
    batch an Aside hands it, the second part by a twin that inherits the preparation (any
    order of results); unpicklable tasks or a used helper: the Aside forks a child of its
    own; an unused helper is killed, an aborted one with its twin; no folder left."""
    assert _fresh(HELPER_CHECK) == "OK"


MAILBOX_CHECK = """
import os, threading, time
from robot_calib.forked import Aside, Mailbox

parent = os.getpid()
# a result sent is handed over at once, not when the child sends the next one
def slow():
    time.sleep(600)
with Aside([("a", os.getpid), ("b", os.getpid), ("c", slow)], timeout_s=20) as aside:
    assert aside.result("a") != parent
    started = time.monotonic()
    assert aside.result("b") != parent  # the child's: not computed here after a timeout
    assert time.monotonic() - started < 10
# a value found later reaches the child's tasks; leaving without putting does not hang
with Mailbox() as box:
    with Aside([("twice", lambda: (box.get() * 2, os.getpid()))], mailbox=box) as aside:
        time.sleep(0.2)
        box.put(21)
        value, pid = aside.result("twice")
        assert value == 42 and pid != parent
with Mailbox() as box:
    with Aside([("never", box.get)], mailbox=box) as aside:
        assert aside.forked  # left without a value: the waiting child is killed
stop = threading.Event()
other = threading.Thread(target=stop.wait)
other.start()
with Mailbox() as box:  # no fork beside a thread: computed here after the put
    with Aside([("twice", lambda: box.get() * 2)], mailbox=box) as aside:
        assert not aside.forked
        box.put(big := "x" * 200_000)  # more than a pipe holds: never written to one
        assert aside.result("twice") == big * 2
stop.set()
other.join()
print("OK")
"""

KILLED_CHECK = """
import os, sys, time, functools
from robot_calib.forked import Aside, Helper

helper = Helper(functools.partial(time.sleep, 0.1))
aside = Aside([("slow", functools.partial(time.sleep, 2))])
print(aside._child[0], helper._child[0], aside._child[2], helper._child[3], flush=True)
time.sleep(60)  # killed here
"""


def test_a_result_is_handed_over_at_once_and_a_mailbox_carries_a_later_value() -> None:
    """A result the child sent is taken at once (was: it waited in a read buffer until the
    child's next one, here never: the timeout, then computed here); a Mailbox value put
    after the fork reaches the child's task; an Aside left before the put ends its
    waiting child; without a fork the value (even beyond a pipe's 64 KiB) is used here."""
    assert _fresh(MAILBOX_CHECK) == "OK"


def test_children_of_a_killed_process_end_and_remove_their_folders() -> None:
    """SIGKILL of the process: its Aside child finishes, finds it gone and removes its
    folder; its idle helper reads end-of-file (no other child holds its batch pipe) and
    does the same; no process, no folder is left."""
    import os
    import signal
    import time

    run = subprocess.Popen([sys.executable, "-c", KILLED_CHECK], stdout=subprocess.PIPE, text=True)
    assert run.stdout is not None
    fields = run.stdout.readline().split()
    children, folders = [int(p) for p in fields[:2]], [Path(f) for f in fields[2:]]
    assert all(f.is_dir() for f in folders)
    run.send_signal(signal.SIGKILL)
    run.wait(timeout=30)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and (
        any(f.exists() for f in folders)
        or any(
            Path(f"/proc/{p}").exists()
            and "Z" not in Path(f"/proc/{p}/stat").read_text().split(")")[-1].split()[:1]
            for p in children
        )
    ):
        time.sleep(0.2)
    assert not any(f.exists() for f in folders), folders
    for pid in children:
        try:
            os.kill(pid, 0)
            state = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
            assert state == "Z", (pid, state)  # ended (a zombie until init reaps it)
        except (ProcessLookupError, FileNotFoundError):
            pass


KFOLD_CHECK = """
import threading
import numpy as np
from robot_calib import forked as forking, parallel
from robot_calib.diagnosis.ladder import kfold_parameters
from robot_calib.diagnosis.learnable import corrected_heldout
from robot_calib.identify.calibrate import calibrate
from robot_calib.sim.scenarios import ur10_random

effects = ({"name": "compliance", "joints": [2, 3],
            "values": {"compliance2": 2e-5, "compliance3": 2e-5}},)
received = []
class Counted(forking.Aside):
    def close(self, abort=False):
        super().close(abort)
        received.append(self.received)
class CountedRunner(forking.Forked):  # the forked runner, counting what its child sent
    def aside(self, tasks, mailbox=None):
        return Counted(tasks, mailbox=mailbox)
scenario = ur10_random(seed=1, n=500, effects=effects)
recording = scenario.calibration
geo = calibrate(recording, scenario.world.model.robot, "geometric")
fold, fitted = kfold_parameters(geo, recording)
with parallel.using(CountedRunner()):
    forked = corrected_heldout(geo, recording, None, fold, fitted, final=False)
assert received == [6], received  # the other folds' geometry, then two folds, aside
stop = threading.Event()
other = threading.Thread(target=stop.wait)
other.start()  # another thread: everything computed in this process
with parallel.using(CountedRunner()):
    here = corrected_heldout(geo, recording, None, fold, fitted, final=False)
assert received[1:] == [0], received
stop.set()
other.join()
for a, b in zip(forked[:2], here[:2]):
    assert a.shape == b.shape and np.allclose(a, b, rtol=0, atol=1e-12), np.abs(a - b).max()
assert forked[2].hyper.vector().tolist() == here[2].hyper.vector().tolist()
assert forked[2].warnings == here[2].warnings
print(f"{np.sqrt(np.mean(np.sum(forked[1] ** 2, axis=1))) * 1e3:.4f}")
"""


def test_the_k_folds_fitted_aside_equal_the_folds_fitted_here() -> None:
    """The hybrid correction's nested k-fold (`corrected_heldout`) with the folds shared
    between this process and a forked child gives the held-out residuals, hyperparameters
    and warnings of the same k-fold computed in one process (to 1e-12 m), and learns the
    compliance the geometry lacks (held-out rms well below geometric's ~0.9 mm)."""
    assert float(_fresh(KFOLD_CHECK)) < 0.3


def test_a_folder_left_by_a_killed_process_is_removed_by_the_next(tmp_path: Path) -> None:
    """A child that ended before its parent was killed leaves its folder (nobody removes
    it then): the next private folder made there removes every folder whose writer is
    gone, never one of a running process."""
    import socket

    from robot_calib import atomic
    from robot_calib.forked import FOLDER_PREFIX

    ended = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    left = tmp_path / f"{FOLDER_PREFIX}left"
    left.mkdir()
    (left / atomic.OWNER_FILE).write_text(f"{socket.gethostname()} {ended.stdout.strip()} 1")
    (left / "0").write_bytes(b"a result never read")
    running = tmp_path / f"{FOLDER_PREFIX}running"
    running.mkdir()
    (running / atomic.OWNER_FILE).write_text(atomic._writer_id())
    new = atomic.owned_folder(tmp_path, FOLDER_PREFIX)
    assert not left.exists() and running.exists() and new.is_dir()
