"""Shared fixtures: the shared real meshes and the CLI built beside the module."""

import os
import pathlib
import subprocess
import threading

import pytest

import crumple

REPO = pathlib.Path(__file__).resolve().parents[2]


def _data_dir() -> pathlib.Path:
    env = os.environ.get("CRUMPLE_DATA_DIR")
    return pathlib.Path(env) if env else (REPO.parent / "shared" / "data").resolve()


@pytest.fixture(scope="session")
def data() -> pathlib.Path:
    """The shared real-mesh folder. Fails (does not skip) when missing: these checks must not
    pass silently."""
    d = _data_dir()
    assert d.is_dir(), (f"{d} does not exist: the real-mesh tests need the shared data folder "
                        "(set CRUMPLE_DATA_DIR=/path/to/shared/data)")
    return d


@pytest.fixture(scope="session")
def cli() -> pathlib.Path:
    """The `crumple` CLI of the build the imported module comes from
    (build/<preset>/python/crumple/ -> build/<preset>/apps/cli/crumple)."""
    env = os.environ.get("CRUMPLE_CLI")
    path = pathlib.Path(env) if env else (
        pathlib.Path(crumple.__file__).resolve().parents[2] / "apps" / "cli" / "crumple")
    assert path.is_file(), f"{path} not found: build the crumple_cli target (or set CRUMPLE_CLI)"
    return path


def run_cli(cli: pathlib.Path, *args) -> str:
    done = subprocess.run([str(cli), *map(str, args)], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    return done.stdout


def probes_refused_during(probe, work) -> int:
    """Runs work() while another thread calls probe() in a loop; returns how many probes were
    refused with RuntimeError "in use". An object refuses calls exactly while a call into C++
    is under way on it, so a count above 0 shows that call released the GIL (with the GIL held
    no probe could run). Iterations are counted, not timed."""
    started, finished = threading.Event(), threading.Event()
    refused = []

    def watch():
        started.set()
        n = 0
        while not finished.is_set():
            try:
                probe()
            except RuntimeError as e:
                assert "in use" in str(e)
                n += 1
        refused.append(n)

    watcher = threading.Thread(target=watch)
    watcher.start()
    started.wait()
    try:
        work()
    finally:
        finished.set()
        watcher.join()
    return refused[0]
