"""Continuous collision detection between two real frames: the impacts' times of impact as a
histogram, and the collision-free step.

    PYTHONPATH=build/release/python /usr/bin/python3 examples/python/ccd_toi.py \
        [FRAME0 FRAME1] [--min-separation-rel 1e-3] [--method kdop] [--out toi.png]

Without frames, uses cloth-funnel frames 227 -> 228 from ../shared/data (what `crumple ccd A B
--min-separation-rel 1e-3` does).
"""

import argparse
import pathlib

import matplotlib

matplotlib.use("Agg")  # writes a file, needs no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import crumple  # noqa: E402

DATA = pathlib.Path(__file__).resolve().parents[2].parent / "shared" / "data"
FUNNEL = DATA / "sample-scalable-ccd" / "cloth-funnel" / "frames"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frames", nargs="*", type=pathlib.Path,
                        default=[FUNNEL / "227.ply", FUNNEL / "228.ply"])
    parser.add_argument("--min-separation-rel", type=float, default=1e-3,
                        help="delta as a multiple of the first frame's bounding-box diagonal")
    parser.add_argument("--method", default="kdop", help="kdop, hash or sap, with parameters")
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("toi.png"))
    args = parser.parse_args()

    m0, m1 = (crumple.read_mesh(p) for p in args.frames[:2])
    x0, x1 = m0.vertices, m1.vertices
    delta = args.min_separation_rel * float(np.linalg.norm(x0.max(axis=0) - x0.min(axis=0)))
    impacts = crumple.continuous_impacts(m0, x0, x1, min_separation=delta, method=args.method,
                                         threads=args.threads)

    fig, ax = plt.subplots(figsize=(7, 4), dpi=110)
    bins = np.linspace(0, 1, 41)
    ax.hist(impacts.ee.toi, bins=bins, alpha=0.6, label=f"edge-edge ({len(impacts.ee)})")
    ax.hist(impacts.vf.toi, bins=bins, alpha=0.6, label=f"vertex-face ({len(impacts.vf)})")
    ax.set_xlabel("time of impact (0 = first frame, 1 = second)")
    ax.set_ylabel("impacts")
    ax.set_title(f"{args.frames[0].name} -> {args.frames[1].name}: delta = {delta:.4g}, "
                 f"collision-free step {impacts.collision_free_step:.4g}")
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out)
    print(f"{impacts} step={impacts.collision_free_step!r} -> {args.out}")


if __name__ == "__main__":
    main()
