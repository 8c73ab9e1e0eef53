"""Warming the fast path (solvers/compiled/warm.py, solvers.on_path_for_a_command): a first run (solver.path auto)
whose method's stepper is not compiled yet is served by the reference path with a note, while a background process
compiles the stepper; the next run is on the fast path. A scene that names the fast path compiles first. That is what the scene default solver.path auto does (test/conftest.py fixes auto to
the reference path for the rest of the suite; these cases take that away). A method the fast path does not have
falls back with a note; a scene on the reference path is left alone; MECH_REGULATOR_AUTO_PATH fixes what auto means.

numba reads NUMBA_CACHE_DIR when it is imported, so each case runs in a fresh Python with empty caches of its own.
The cold first run's caches hold all of the package's compiled functions but the steppers (stepper_only_missing): the
background compile is then the RK4 stepper's own part (its integration loop and callees load from the cache), a few
seconds of CPU rather than a whole cold compile's some 45 s, and the stepper is as missing to the command as in a
fresh clone (stepper_cached reads the stepper's own index).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from numba.core.caching import _CacheLocator

from mech_regulator import numba_cache
from mech_regulator.processes import command_line_child, python_child

WAIT = 300.0  # [s] of wall time: the failure limit of the background compile (never what the test measures)

CHOOSE = """
import json, sys
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene
from mech_regulator.solvers import on_path_for_a_command
from mech_regulator.solvers.compiled.warm import stepper_cached

notes = []
model = on_path_for_a_command(build_model(load_scene("lathe", sys.argv[1:])), notes.append)
print(json.dumps({"path": model.scene.solver.path, "notes": notes, "cached": stepper_cached("RK4")}))
"""


def choose(environment: dict[str, str], *overrides: str) -> dict:
    """What on_path_for_a_command chose for the lathe with these overrides, in a fresh Python."""
    result = subprocess.run(
        [sys.executable, "-c", CHOOSE, *overrides],
        capture_output=True,
        text=True,
        timeout=120,
        env=environment,
        check=True,
    )
    return json.loads(result.stdout)


@pytest.fixture
def empty_caches(tmp_path) -> dict[str, str]:
    (tmp_path / "numba").mkdir()
    (tmp_path / "compiled").mkdir()
    environment = dict(
        os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), MECH_REGULATOR_CACHE=str(tmp_path / "compiled")
    )
    environment.pop("MECH_REGULATOR_AUTO_PATH", None)  # the product's default, not the suite's (conftest.py)
    return environment


@pytest.fixture
def stepper_only_missing(empty_caches) -> dict[str, str]:
    """empty_caches with the package's numba cache copied into its NUMBA_CACHE_DIR, laid out as numba reads it there
    (a folder per source folder: numba's _CacheLocator.get_suitable_cache_subpath), all but the steppers' files.
    The package's cache is the suite's own (__pycache__ beside the modules), the RK4 stepper compiled in it first
    (or loaded: the rest of the suite runs it too), so that its callees are there. Should numba lay its cache out
    otherwise, nothing is found under the copies' names and the stepper compiles wholly cold: slower, the same test."""
    from mech_regulator.solvers.compiled.steppers import stepper

    stepper("RK4")
    target = Path(empty_caches["NUMBA_CACHE_DIR"])
    for cached in numba_cache.PACKAGE_ROOT.rglob("__pycache__/*.nb[ic]"):
        if not cached.name.startswith("steppers."):
            source_file = cached.parent.parent / f"{cached.name.split('.')[0]}.py"
            folder = target / _CacheLocator.get_suitable_cache_subpath(str(source_file))
            folder.mkdir(exist_ok=True)
            shutil.copy2(cached, folder)
    return empty_caches


def test_a_cold_first_run_uses_the_reference_path_while_the_stepper_compiles(stepper_only_missing):
    caches = stepper_only_missing
    fast_rk4 = ("solver.method=RK4", "solver.step=0.001")  # solver.path: auto, the default
    first = choose(caches, *fast_rk4)
    assert first["path"] == "reference" and not first["cached"], first
    assert len(first["notes"]) == 1 and "now compiling in the background" in first["notes"][0], first
    second = choose(caches, *fast_rk4)  # while it compiles: no second compiling process
    log = os.path.join(caches["MECH_REGULATOR_CACHE"], "compiling.log")
    deadline = time.monotonic() + WAIT
    while not (os.path.exists(log) and "RK4 ready" in open(log).read()):
        assert time.monotonic() < deadline, f"the background compile did not finish: {open(log).read()}"
        time.sleep(0.5)
    assert second["path"] == "fast" or "is compiling in the background" in second["notes"][0], second
    assert open(log).read().count("compiling the fast path's RK4 stepper") == 1, open(log).read()
    warm = choose(caches, *fast_rk4)
    assert warm == {"path": "fast", "notes": [], "cached": True}


def test_a_method_the_fast_path_lacks_falls_back_with_a_note(empty_caches):
    chosen = choose(empty_caches, "solver.path=fast", "solver.method=LSODA")
    assert chosen["path"] == "reference" and "solver.method: 'LSODA'" in chosen["notes"][0], chosen
    assert not os.path.exists(os.path.join(empty_caches["MECH_REGULATOR_CACHE"], "compiling.log"))


def test_the_reference_path_is_left_alone(empty_caches):
    assert choose(empty_caches, "solver.path=reference") == {"path": "reference", "notes": [], "cached": False}


def test_auto_and_fast_fall_back_alike_for_a_method_the_fast_path_lacks(empty_caches):
    chosen = choose(empty_caches, "solver.method=LSODA")
    assert chosen["path"] == "reference" and "solver.method: 'LSODA'" in chosen["notes"][0], chosen


def test_the_auto_path_variable_fixes_what_auto_means(empty_caches):
    pinned = dict(empty_caches, MECH_REGULATOR_AUTO_PATH="reference")
    assert choose(pinned, "solver.method=RK4", "solver.step=0.001") == {
        "path": "reference",
        "notes": [],
        "cached": False,
    }
    assert not os.path.exists(os.path.join(empty_caches["MECH_REGULATOR_CACHE"], "compiling.log"))
    wrong = subprocess.run(
        [sys.executable, "-m", "mech_regulator", "simulate", "lathe", "--quiet"],
        text=True,
        capture_output=True,
        timeout=120,
        env=dict(empty_caches, MECH_REGULATOR_AUTO_PATH="quick"),
    )
    assert wrong.returncode == 2, wrong.stderr
    assert "MECH_REGULATOR_AUTO_PATH='quick': expected reference or fast" in wrong.stderr
    assert "Traceback" not in wrong.stderr


@pytest.mark.parametrize(
    ("path", "compile_now"),
    [("auto", True), ("fast", False)],
    ids=["the main job (compile_now)", "a scene that names the fast path"],
)
def test_a_stepper_is_compiled_before_the_run_that_needs_it(monkeypatch, path, compile_now):
    """compile_now (the main job), or a scene that asks for the fast path by name: a stepper not compiled yet is
    compiled here, announced, and the run takes the fast path the scene asked for; no background compile is started
    (it would compete with the nodes) and the run is not moved to the reference path."""
    from mech_regulator.model import build_model
    from mech_regulator.scene import load_scene
    from mech_regulator.solvers import compiled, on_path_for_a_command
    from mech_regulator.solvers.compiled import warm

    monkeypatch.delenv("MECH_REGULATOR_AUTO_PATH", raising=False)
    compiled_here = []
    monkeypatch.setattr(warm, "stepper_cached", lambda method: False)
    monkeypatch.setattr(warm, "compile_before_the_run", lambda method, report: compiled_here.append(method))
    monkeypatch.setattr(warm, "compile_in_background", lambda methods: pytest.fail("a background compile"))
    model = build_model(load_scene("lathe", ["solver.method=DOP853", f"solver.path={path}"]))
    assert compiled.fast_path_refusal(model) is None
    notes = []
    chosen = on_path_for_a_command(model, notes.append, compile_now=compile_now)
    assert chosen.scene.solver.path == "fast" and compiled_here == ["DOP853"], notes


def test_a_compile_under_way_is_waited_for_not_run_twice(monkeypatch, tmp_path):
    """compile_before_the_run while another process holds the compile lock: it says it waits; the compile runs in a
    child process (this module's main, which takes the lock, waiting for the other's compile, then loads it)."""
    import fcntl

    from mech_regulator.solvers.compiled import locks, warm

    monkeypatch.setenv("MECH_REGULATOR_CACHE", str(tmp_path))
    children = []

    def child(argv, **options):
        children.append(argv)
        return subprocess.CompletedProcess(argv, 0, "", "")

    monkeypatch.setattr(warm.subprocess, "run", child)
    monkeypatch.setattr(warm, "stepper_cached", lambda method: True)  # as the child leaves it
    lines = []
    warm.compile_before_the_run("RK4", lines.append)
    assert lines[0] == f"compiling the fast path's RK4 stepper (once, {warm.compile_estimate('RK4')}) ...", lines
    with open(locks.lock_path(), "a") as other:  # another process's background compile
        fcntl.flock(other, fcntl.LOCK_EX)
        warm.compile_before_the_run("RK4", lines.append)
    assert lines[2].startswith("waiting for the fast path's RK4 stepper that another process is compiling"), lines
    assert children == [python_child(warm.CHILD_PROGRAM, "RK4")] * 2
    assert re.fullmatch(r"RK4 ready in [0-9.]+ s", lines[3]), lines


def test_a_stepper_is_compiled_or_loaded_under_its_methods_lock_only(monkeypatch, tmp_path):
    """steppers.stepper holds its method's lock while numba compiles or loads the stepper (so that a second
    process, a test worker beside this one, waits and loads it instead of compiling it again), and no other method's
    lock nor the background compile's."""
    import fcntl

    from mech_regulator.solvers.compiled import locks, steppers

    monkeypatch.setenv("MECH_REGULATOR_CACHE", str(tmp_path))

    def held(path: Path) -> bool:
        with open(path, "a") as other:
            try:
                fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                return True
            return False

    seen = []

    def compiling(signature, cache):  # numba's njit, looking at the locks instead of compiling
        def compile_(function):
            seen.append([held(path) for path in (rk4_lock, locks.method_lock_path("DOP853"), locks.lock_path())])
            return function

        return compile_

    rk4_lock = locks.method_lock_path("RK4")
    assert rk4_lock.parent == tmp_path
    monkeypatch.setattr(steppers, "njit", compiling)
    steppers.stepper.__wrapped__("RK4")  # not functools.cache's: this process's compiled stepper is left alone
    assert seen == [[True, False, False]]
    assert not held(rk4_lock)  # released once loaded


@pytest.mark.parametrize(
    ("cached", "expected"),
    [((), "FIRST"), (("RK4",), "FIRST"), (("DOP853",), "FURTHER"), (("RK4", "RK45", "Rosenbrock23"), "FURTHER")],
)
def test_a_compile_is_announced_with_what_it_takes_here(monkeypatch, cached, expected):
    """The first stepper compiles the integration loop the methods share (about 50 s), a further one not (about
    10 s): the estimate a compile is announced with says which, from what numba's disk cache holds besides it."""
    from mech_regulator.solvers.compiled import warm

    monkeypatch.setattr(warm, "stepper_cached", lambda method: method in cached)
    assert warm.compile_estimate("RK4") == getattr(warm, f"{expected}_COMPILE_ESTIMATE")


def test_another_versions_compile_does_not_hold_a_stepper_up(monkeypatch, tmp_path):
    """Two versions of the package sharing a cache folder (two checkouts): the locks carry the stamp of the compiled
    code's sources, so a stepper of this version is compiled or loaded while another version's compile of the same
    method holds its own lock (before, the run waited minutes behind it, silently)."""
    import fcntl

    from mech_regulator.solvers.compiled import locks

    monkeypatch.setenv("MECH_REGULATOR_CACHE", str(tmp_path))
    monkeypatch.setattr(locks, "reach_source_hash", lambda: "a" * 64)
    other_version = locks.method_lock_path("RK4"), locks.lock_path()
    monkeypatch.setattr(locks, "reach_source_hash", lambda: "b" * 64)
    assert other_version == (tmp_path / f"compiling-{'a' * 16}-RK4.lock", tmp_path / f"compiling-{'a' * 16}.lock")
    with open(other_version[0], "a") as other:
        fcntl.flock(other, fcntl.LOCK_EX)
        with locks.method_lock("RK4"), open(locks.method_lock_path("RK4"), "a") as mine:
            with pytest.raises(BlockingIOError):  # this version's lock is held here, by method_lock
                fcntl.flock(mine, fcntl.LOCK_EX | fcntl.LOCK_NB)


def test_a_wait_for_another_process_s_compile_is_said_and_timed(monkeypatch, tmp_path, capsys):
    """A stepper's lock held by another process (its compile): method_lock says on stderr that it waits, for what,
    and, once the lock is free, how long it waited; a free lock is taken saying nothing."""
    import fcntl
    import threading

    from mech_regulator.solvers.compiled import locks

    monkeypatch.setenv("MECH_REGULATOR_CACHE", str(tmp_path))
    with locks.method_lock("RK4"):
        pass
    assert capsys.readouterr().err == ""
    held = threading.Event()
    with open(locks.method_lock_path("RK4"), "a") as other:
        fcntl.flock(other, fcntl.LOCK_EX)
        release = threading.Timer(0.3, lambda: (held.set(), fcntl.flock(other, fcntl.LOCK_UN)))  # set, then free
        release.start()
        with locks.method_lock("RK4"):
            assert held.is_set()
        release.join()
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2, lines
    assert lines[0].startswith("mech-regulator: waiting for another process's compile of the fast path's RK4 stepper")
    assert str(locks.method_lock_path("RK4")) in lines[0]
    assert re.fullmatch(r"  RK4 stepper free after ([0-9.]+) s", lines[1]) and float(lines[1].split()[-2]) >= 0.25


def test_a_scene_module_compiled_for_the_first_time_is_announced(tmp_path):
    """A scene's generated module new to the cache folder: a note before numba compiles it; none once it is there.
    In a fresh Python with empty caches (numba reads NUMBA_CACHE_DIR as it is imported)."""
    script = (
        "from mech_regulator.model import build_model; from mech_regulator.scene import load_scene; "
        "from mech_regulator.solvers.compiled.codegen import compile_scene; "
        "compile_scene(build_model(load_scene('lathe')))"
    )
    environment = dict(
        os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), MECH_REGULATOR_CACHE=str(tmp_path / "compiled")
    )
    notes = [
        subprocess.run(
            [sys.executable, "-c", script], capture_output=True, text=True, timeout=300, env=environment, check=True
        ).stderr
        for _ in range(2)
    ]
    assert notes[0] == (
        "note: compiling the fast path's module of scene 'lathe' once (a few seconds; later runs load it at once)\n"
    ), notes[0]
    assert notes[1] == "", notes[1]


@pytest.fixture
def decoy_checkout(tmp_path, monkeypatch) -> Path:
    """A working folder holding another copy of the package (a checkout beside the installed package the command
    runs), one that only says it was imported: the folder the processes under test start in, with a cache folder of
    their own."""
    decoy = tmp_path / "checkout" / "mech_regulator"
    decoy.mkdir(parents=True)
    (decoy / "__init__.py").write_text("import sys\nprint('the decoy copy was imported')\nsys.exit(3)\n")
    monkeypatch.chdir(decoy.parent)
    monkeypatch.setenv("MECH_REGULATOR_CACHE", str(tmp_path / "compiled"))
    return decoy


def test_the_compile_before_the_run_compiles_the_package_that_runs(decoy_checkout):
    """The main job's compile child imports the package its parent runs, not another copy in the working folder
    (`python -m` imported that one: the child compiled it, and the main job compiled its own stepper a second time
    after the announced compile, silently, 45 s and more). A method no stepper has makes the real child answer at once
    with its refusal."""
    from mech_regulator.solvers.compiled import warm

    with pytest.raises(RuntimeError) as failed:
        warm.compile_before_the_run("Euler", lambda line: None)
    assert "unknown fast-path method(s) ['Euler']" in str(failed.value), failed.value
    assert "decoy" not in str(failed.value)


def test_the_background_compile_compiles_the_package_that_runs(decoy_checkout):
    """The same for the background compile (else every later run found its stepper still missing: the reference path
    and another background compile, run after run)."""
    import fcntl

    from mech_regulator.solvers.compiled import locks, warm

    assert warm.compile_in_background(["Euler"])
    log = locks.lock_path().with_name("compiling.log")
    deadline = time.monotonic() + WAIT
    while not (log.exists() and log.read_text()):
        assert time.monotonic() < deadline, "the background process wrote nothing"
        time.sleep(0.1)
    with open(locks.lock_path(), "a") as lock:  # held until the background process ends
        fcntl.flock(lock, fcntl.LOCK_EX)
    assert "unknown fast-path method(s) ['Euler']" in log.read_text(), log.read_text()
    assert "decoy" not in log.read_text()


def test_a_python_child_imports_what_this_process_imports(decoy_checkout):
    """processes.python_child: the child's sys.path is this process's, whatever folder it starts in."""
    import mech_regulator

    child = subprocess.run(
        python_child("import mech_regulator; print(mech_regulator.__file__)"),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert child.stdout == f"{mech_regulator.__file__}\n", child.stdout + child.stderr


def test_a_command_line_child_runs_the_package_this_process_runs(decoy_checkout):
    """processes.command_line_child (the benchmarks' `run` children): `mech-regulator ARGUMENTS` with this process's
    package, not `python -m mech_regulator`'s copy in the working folder, and its argument list as given."""
    child = subprocess.run(command_line_child("describe", "lathe"), capture_output=True, text=True, timeout=120)
    assert child.returncode == 0, child.stdout + child.stderr
    assert "decoy" not in child.stdout + child.stderr
    assert "lathe" in child.stdout
    wrong = subprocess.run(command_line_child("describe", "no_such_scene"), capture_output=True, text=True, timeout=120)
    assert wrong.returncode == 2, wrong.stdout + wrong.stderr
    assert "no_such_scene" in wrong.stderr


def test_a_stepper_still_missing_after_the_childs_compile_is_compiled_here_announced(monkeypatch, tmp_path):
    """Should the main job still not find the stepper in numba's disk cache after the child's compile (the package's
    sources changed since the main job read them), it says so and compiles it itself, announced with its
    estimate, rather than leaving the compile to the first exchange, unannounced."""
    from mech_regulator.solvers.compiled import steppers, warm

    monkeypatch.setenv("MECH_REGULATOR_CACHE", str(tmp_path))
    monkeypatch.setattr(warm.subprocess, "run", lambda argv, **options: subprocess.CompletedProcess(argv, 0, "", ""))
    monkeypatch.setattr(warm, "stepper_cached", lambda method: False)
    compiled_here = []
    monkeypatch.setattr(steppers, "stepper", compiled_here.append)
    lines = []
    warm.compile_before_the_run("DOP853", lines.append)
    assert compiled_here == ["DOP853"]
    assert "is not in numba's disk cache as this process reads it" in lines[2], lines
    assert lines[3] == f"compiling the fast path's DOP853 stepper (once, {warm.compile_estimate('DOP853')}) ...", lines
    assert re.fullmatch(r"  DOP853 ready in [0-9.]+ s", lines[4]), lines


EXCHANGE_WORK = """
import json
from numba.core.event import install_recorder
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene
from mech_regulator.solvers.compiled.dense import steps_dense
from mech_regulator.solvers.compiled.events import _switch_window
from mech_regulator.solvers.compiled.pieces import compiled_speeds_one_cycle_back, sampled_speeds, speed_rows
from mech_regulator.solvers.compiled.steppers import stepper
from mech_regulator.solvers.cosim import DEFAULT_COUPLING, cosimulate, load_steppers

model = build_model(load_scene("engine_direct", ["solver.path=fast"]))
stepper(model.scene.solver.method)  # what the announced compile compiles (warm.compile_before_the_run's child)
dense_with_the_stepper = [str(signature) for signature in steps_dense.signatures]
pieces_with_the_stepper = [str(signature) for signature in speed_rows.signatures]
machine_with_the_stepper = [
    str(signature) for kernel in (sampled_speeds, compiled_speeds_one_cycle_back) for signature in kernel.signatures
]
window_with_the_stepper = [str(signature) for signature in _switch_window.signatures]
load_steppers(model, model.scene.solver.exchange_step)
with install_recorder("numba:compiler_lock") as numba_work:
    run = cosimulate(model, model.scene.solver.exchange_step, coupling=DEFAULT_COUPLING)
print(json.dumps({
    "status": run.status,
    "dense output with the stepper": dense_with_the_stepper,
    "dense output at the end": [str(signature) for signature in steps_dense.signatures],
    "speed pieces with the stepper": pieces_with_the_stepper,
    "speed pieces at the end": [str(signature) for signature in speed_rows.signatures],
    "machine's samples with the stepper": machine_with_the_stepper,
    "machine's samples at the end": [
        str(signature) for kernel in (sampled_speeds, compiled_speeds_one_cycle_back) for signature in kernel.signatures
    ],
    "switch window with the stepper": window_with_the_stepper,
    "switch window at the end": [str(signature) for signature in _switch_window.signatures],
    "numba work at the exchanges": len(numba_work.buffer),
}))
"""


def test_what_the_main_jobs_nodes_run_is_compiled_before_they_start():
    """The main job compiles its stepper in the announced compile, then its launcher calls load_steppers before it
    forks the nodes (nodes/launch.py): what the nodes' exchanges run must all be compiled and loaded by then, else each
    node compiles (cold: seconds to tens of seconds, two nodes at once on two cores, unannounced) or loads it for
    itself. In a fresh Python (nothing loaded by other tests), engine_direct's co-simulation as the nodes run it (their
    default coupling, the scene's exchange step): the evaluation of the dense output, which every exchange reads, and
    the governor's speed pieces (pieces.speed_rows), the machine's speed samples and its prediction one cycle back
    (pieces.sampled_speeds, pieces.compiled_speeds_one_cycle_back) and the switch window a compiled call starts in
    (events._switch_window, called from Python) are compiled with the stepper, for the argument types the run
    gives them (the first compiled at its first call, some 1 s of CPU cold after the announced compile); and numba takes its compiler lock, which it takes for every compile and
    every load from its disk cache, not once at the exchanges after load_steppers (measured without the
    load_steppers call: 40 times)."""
    child = subprocess.run(
        [sys.executable, "-c", EXCHANGE_WORK], capture_output=True, text=True, timeout=WAIT, check=True
    )
    outcome = json.loads(child.stdout)
    assert outcome["status"] == "complete", outcome
    assert len(outcome["dense output with the stepper"]) == 1, outcome
    assert outcome["dense output at the end"] == outcome["dense output with the stepper"], outcome
    assert len(outcome["speed pieces with the stepper"]) == 1, outcome
    assert outcome["speed pieces at the end"] == outcome["speed pieces with the stepper"], outcome
    assert len(outcome["machine's samples with the stepper"]) == 2, outcome
    assert outcome["machine's samples at the end"] == outcome["machine's samples with the stepper"], outcome
    assert len(outcome["switch window with the stepper"]) == 1, outcome
    assert outcome["switch window at the end"] == outcome["switch window with the stepper"], outcome
    assert outcome["numba work at the exchanges"] == 0, outcome
