"""The Python examples run and write what they say."""

import os
import pathlib
import subprocess
import sys

import crumple

EXAMPLES = pathlib.Path(__file__).resolve().parents[2] / "examples" / "python"


def run_example(name, *args):
    env = dict(os.environ, PYTHONPATH=str(pathlib.Path(crumple.__file__).parents[1]))
    done = subprocess.run([sys.executable, str(EXAMPLES / name), *map(str, args)],
                          env=env, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    return done.stdout


def is_png(path):
    return path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_detect_histogram_writes_a_png(tmp_path, data):
    out = tmp_path / "d.png"
    stdout = run_example("detect_histogram.py",
                         data / "sample-scalable-ccd/cloth-funnel/frames/227.ply",
                         "--threads", 2, "--out", out)
    assert "Contacts(vf=" in stdout
    assert is_png(out)


def test_recall_budget_writes_a_png(tmp_path):
    out = tmp_path / "r.png"
    stdout = run_example("recall_budget.py", "--scene", "hanging-cloth:nx=8,ny=8", "--frames", 50,
                         "--budgets", "4,64", "--threads", 1, "--out", out)
    recalls = [float(line.split()[2]) for line in stdout.splitlines() if line.startswith("active=")]
    assert len(recalls) == 2 and all(0 <= r <= 1 for r in recalls) and recalls[1] > 0.5, stdout
    assert is_png(out)


def test_simulate_cloth_writes_a_png(tmp_path):
    out = tmp_path / "c.png"
    stdout = run_example("simulate_cloth.py", "--scene", "cloth-on-sphere:n=6", "--frames", 3,
                         "--size", "64x48", "--threads", 1, "--out", out)
    assert "frame=3" in stdout
    assert is_png(out)


def test_ccd_toi_writes_a_png(tmp_path):
    out = tmp_path / "t.png"
    stdout = run_example("ccd_toi.py", "--threads", 2, "--out", out)
    assert "Impacts(vf=" in stdout and "step=" in stdout
    assert is_png(out)
