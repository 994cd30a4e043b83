"""The README's Python section runs as written: its snippets are executed on a real mesh's
arrays, and the five-line detection gives the CLI's `detect` contacts and writes its plot."""

import pathlib
import re
import subprocess

import matplotlib
import numpy as np

import crumple
from conftest import REPO, run_cli

matplotlib.use("Agg")  # the snippet's plt.savefig needs no display

FUNNEL = ["sample-scalable-ccd/cloth-funnel/frames/227.ply",
          "sample-scalable-ccd/cloth-funnel/frames/228.ply"]


def python_snippets():
    """The ```python blocks of the README's "## Python" section, in order."""
    text = (REPO / "README.md").read_text()
    section = re.search(r"^## Python\n(.*?)(?=^## )", text, re.S | re.M)
    assert section, "README.md has no '## Python' section"
    return re.findall(r"^```python\n(.*?)^```", section.group(1), re.S | re.M)


def test_readme_python_section_runs_and_detects_as_the_cli(tmp_path, cli, data, monkeypatch):
    detect, ccd, simulate = python_snippets()
    assert len([line for line in detect.splitlines() if line.strip()]) == 5  # "in five lines"
    previous_mesh, mesh = (crumple.read_mesh(data / p) for p in FUNNEL)
    # The user's own arrays: plain NumPy, float32 positions and int64 faces.
    vertices = np.array(mesh.vertices, dtype=np.float32)
    faces = np.array(mesh.faces, dtype=np.int64)
    monkeypatch.chdir(tmp_path)
    scope = {"vertices": vertices, "faces": faces,
             "previous": np.array(previous_mesh.vertices, dtype=np.float32)}
    exec(compile(detect, "README.md: detect", "exec"), scope)  # noqa: S102 -- the README's own code
    assert (tmp_path / "distances.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # What `crumple detect` gives for the same positions (float32 values as a file's doubles).
    frame = tmp_path / "frame.ply"
    crumple.write_mesh(frame, crumple.TriMesh(vertices.astype(np.float64), faces))
    run_cli(cli, "detect", frame, "--method", "kdop", "--kinds", "vf,ee", "--contacts", tmp_path / "cli.tsv")
    scope["c"].write(tmp_path / "mine.tsv")
    text = (tmp_path / "cli.tsv").read_text()
    assert (tmp_path / "mine.tsv").read_text() == text and len(scope["c"].vf) > 1000

    exec(compile(ccd, "README.md: ccd", "exec"), scope)  # noqa: S102
    assert isinstance(scope["i"], crumple.Impacts) and 0 <= scope["i"].collision_free_step <= 1

    exec(compile(simulate, "README.md: simulate", "exec"), scope)  # noqa: S102
    assert scope["stats"]["vf"].shape == (50,)
    picture = scope["picture"]
    assert picture.shape == (480, 640, 3) and picture.dtype == np.uint8


def test_the_demo_prints_a_working_import_line():
    """`bash scripts/dev.sh demo` builds the module and prints how to import it; that line runs
    (with the module of this build in place of the demo's build/release/python)."""
    script = (REPO / "scripts" / "dev.sh").read_text()
    assert re.search(r"--target crumple_cli \$PYTHON_TARGET", script)
    line = re.search(r"^  (PYTHONPATH=\$PWD/build/release/python /usr/bin/python3 .*)$", script, re.M)
    assert line, "the demo prints no PYTHONPATH line"
    module_dir = pathlib.Path(crumple.__file__).resolve().parents[1]
    command = line.group(1).replace("$PWD/build/release/python", str(module_dir))
    done = subprocess.run(["bash", "-c", command], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    counts = [int(v) for v in re.fullmatch(r"\[([\d\s]+)\]\n", done.stdout).group(1).split()]
    assert len(counts) == 10 and max(counts) > 0, done.stdout  # edge-edge contacts as it falls
