"""Detect the self-contacts of a real frame and plot the histogram of their distances.

    PYTHONPATH=build/release/python /usr/bin/python3 examples/python/detect_histogram.py \
        [FRAME [NEXT_FRAME]] [--method kdop] [--out distances.png]

Without FRAME, uses cloth-funnel frames 227 -> 228 from ../shared/data. With two frames the
second is detected with the first as motion (what `crumple detect A B` does).
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
    parser.add_argument("--method", default="kdop", help="the CLI's --method spec")
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("distances.png"))
    args = parser.parse_args()

    meshes = [crumple.read_mesh(p) for p in args.frames[:2]]
    h = crumple.default_thickness(meshes[0].vertices)
    detector = crumple.Detector(args.method, thickness=h, threads=args.threads)
    detector.set_topology(meshes[0])
    contacts = detector.update(*[m.vertices for m in meshes])

    fig, ax = plt.subplots(figsize=(7, 4), dpi=110)
    bins = np.linspace(0, h, 41)
    ax.hist(contacts.ee.distance, bins=bins, alpha=0.6, label=f"edge-edge ({len(contacts.ee)})")
    ax.hist(contacts.vf.distance, bins=bins, alpha=0.6, label=f"vertex-face ({len(contacts.vf)})")
    ax.set_xlim(0, h)
    ax.set_xlabel(f"distance (thickness h = {h:.4g})")
    ax.set_ylabel("contacts")
    ax.set_title(f"{args.frames[len(meshes) - 1].name}: {detector.method}, "
                 f"{meshes[0].num_faces} faces")
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out)
    print(f"{contacts} -> {args.out}")


if __name__ == "__main__":
    main()
