"""The Python examples run and write what they say."""

import os
import pathlib
import subprocess
import sys

import crumple

EXAMPLES = pathlib.Path(__file__).resolve().parents[2] / "examples" / "python"


def test_detect_histogram_writes_a_png(tmp_path, data):
    out = tmp_path / "d.png"
    env = dict(os.environ, PYTHONPATH=str(pathlib.Path(crumple.__file__).parents[1]))
    done = subprocess.run([sys.executable, str(EXAMPLES / "detect_histogram.py"),
                           str(data / "sample-scalable-ccd/cloth-funnel/frames/227.ply"),
                           "--threads", "2", "--out", str(out)],
                          env=env, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert "Contacts(vf=" in done.stdout
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
