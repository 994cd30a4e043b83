"""Python `Detector.update` against the C++ call's time, on cloth-ball 92 -> 93.

    PYTHONPATH=build/release/python /usr/bin/python3 bench/python/update_vs_cli.py \
        [--cli build/release/apps/cli/crumple] [--method kdop] [--threads 2] [--repeat 5] \
        [--layout float64|float32|interleaved32] [--frames DIR]

C++: `crumple detect 92.ply 93.ply --json`, the detector's wall time of frame 93 ("ms": one
`update(previous, positions, contacts)` with the contact set of frame 92 reused). Python: a new
detector, `update(x92)`, its result dropped (so the records are reused, as the CLI does), then
the timed `update(x92, x93)` plus building every result array. Runs alternate (CLI, Python)
so that the machine's drift hits both; prints each pair and the ratio of the medians. Also the
Python call's time over the time of the library call inside it (`Detector.last_update_ms`, the
CLI's measure): the binding's own share, which a loaded machine's drift does not blur.
--layout float32 passes float32 arrays, interleaved32 the [:, 0:3] columns of an (n, 8) float32
vertex buffer: both converted once inside the detector, the conversion timed with the update.
"""

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import time

import numpy as np

import crumple

REPO = pathlib.Path(__file__).resolve().parents[2]
FRAMES = REPO.parent / "shared" / "data" / "sample-scalable-ccd" / "cloth-ball" / "frames"


def cli_ms(cli, frames, method, threads):
    out = subprocess.run([str(cli), "detect", *map(str, frames), "--method", method,
                          "--threads", str(threads), "--json"],
                         capture_output=True, text=True, check=True).stdout
    return json.loads(out.splitlines()[-1])["ms"]


def positions(x, layout):
    if layout == "float64":
        return x
    if layout == "float32":
        return x.astype(np.float32)
    buffer = np.zeros((len(x), 8), dtype=np.float32)  # position, normal, uv
    buffer[:, 0:3] = x
    return buffer[:, 0:3]


def python_ms(meshes, method, threads, layout):
    x0, x1 = (positions(m.vertices, layout) for m in meshes)
    det = crumple.Detector(method, thickness=crumple.default_thickness(x0), threads=threads)
    det.set_topology(meshes[0])
    det.update(x0)  # frame 92, result dropped at once
    start = time.perf_counter()
    c = det.update(x0, x1)
    arrays = [c.vf.vertex, c.vf.face, c.vf.distance, c.vf.barycentric, c.vf.normal, c.ee.edges,
              c.ee.vertices, c.ee.s, c.ee.t, c.ee.distance, c.ee.normal, c.tt.faces]
    ms = (time.perf_counter() - start) * 1e3
    assert det.last_positions_conversion == ("none" if layout == "float64" else "detector")
    return ms, det.last_update_ms, len(c)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cli", type=pathlib.Path, default=REPO / "build/release/apps/cli/crumple")
    p.add_argument("--method", default="kdop")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--layout", choices=["float64", "float32", "interleaved32"], default="float64")
    p.add_argument("--frames", type=pathlib.Path, default=FRAMES,
                   help="folder holding cloth_ball92.ply and cloth_ball93.ply")
    args = p.parse_args()
    frames = [args.frames / "cloth_ball92.ply", args.frames / "cloth_ball93.ply"]
    meshes = [crumple.read_mesh(f) for f in frames]
    cs, ps, inner = [], [], []
    for i in range(args.repeat):
        cs.append(cli_ms(args.cli, frames, args.method, args.threads))
        ms, library_ms, contacts = python_ms(meshes, args.method, args.threads, args.layout)
        ps.append(ms)
        inner.append(ms / library_ms)
        print(f"run {i}: C++ {cs[-1]:.1f} ms, Python {ps[-1]:.1f} ms, of which the library call "
              f"{library_ms:.1f} ms ({contacts} contacts)")
    c, q = statistics.median(cs), statistics.median(ps)
    # Each round's Python run over the C++ run just before it: the drift of a loaded machine
    # cancels better within a round than across the medians.
    paired = statistics.median(p / c for p, c in zip(ps, cs))
    print(f"median: C++ {c:.1f} ms, Python {q:.1f} ms, ratio {q / c:.3f}, median of the rounds' "
          f"ratios {paired:.3f} ({args.method}, {args.threads} threads, cloth-ball 93, {args.layout}, "
          f"{args.repeat} rounds, load average {os.getloadavg()[0]:.2f})")
    # The same call from inside: the Python call's time over its own library call's (the CLI's
    # measure); what the binding adds (argument checks, result arrays), whatever the load.
    print(f"Python call / its library call: median {statistics.median(inner):.4f}, "
          f"max {max(inner):.4f}")


if __name__ == "__main__":
    main()
