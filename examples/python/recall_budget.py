"""Run the stochastic detector against the exact one and plot its recall against its budget.

    PYTHONPATH=build/release/python /usr/bin/python3 examples/python/recall_budget.py \
        [--scene hanging-cloth:nx=24,ny=24] [--frames 80] [--budgets 25,100,400,1600] \
        [--out recall.png]

Simulates the scene (the exact `kdop` detector drives the simulation), then replays its frames
through one `stochastic:active=B` detector per budget B (pairs kept per pair type; its state
carries over from frame to frame) and through `kdop`. Recall: the share of the exact contacts
(vertex-face and edge-edge pairs) that the stochastic detector also reports, over the frames
with contacts after a warm-up of a quarter of them.
"""

import argparse
import pathlib

import matplotlib

matplotlib.use("Agg")  # writes a file, needs no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import crumple  # noqa: E402


def pair_keys(contacts, num_faces, num_edges):
    """Each contact as one int64: vertex-face pairs, then edge-edge pairs (disjoint ranges)."""
    vf = contacts.vf.vertex.astype(np.int64) * num_faces + contacts.vf.face
    ee = contacts.ee.edges.astype(np.int64)
    offset = np.int64(1) << 62
    return np.concatenate([vf, offset + ee[:, 0] * num_edges + ee[:, 1]])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="hanging-cloth:nx=24,ny=24",
                        help="built-in scene spec, as `crumple simulate`")
    parser.add_argument("--frames", type=int, default=80)
    parser.add_argument("--budgets", default="25,50,100,200,400,800,1600",
                        help="comma-separated values of the stochastic detector's `active`")
    parser.add_argument("--variant", default="direct", help="stochastic variant (docs/stochastic.md)")
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("recall.png"))
    args = parser.parse_args()
    budgets = [int(b) for b in args.budgets.split(",")]

    sim = crumple.Simulation(args.scene, threads=args.threads)
    frames = [sim.positions]
    for _ in range(args.frames):
        sim.advance()
        frames.append(sim.positions)
    mesh = sim.mesh()
    h = sim.settings["thickness"]

    def replay(method):
        det = crumple.Detector(method, thickness=h, threads=args.threads)
        det.set_topology(mesh)
        out, previous = [], None
        for x in frames:
            c = det.update(x) if previous is None else det.update(previous, x)
            out.append(pair_keys(c, mesh.num_faces, mesh.num_edges))
            previous = x
        return out

    exact = replay("kdop")
    counted = [k for k in range(len(frames) // 4, len(frames)) if len(exact[k])]
    if not counted:
        raise SystemExit(f"{args.scene}: no contacts in {args.frames} frames; give more --frames")
    total = sum(len(exact[k]) for k in counted)
    recall = []
    for b in budgets:
        found = replay(f"stochastic:active={b},variant={args.variant}")
        hits = sum(np.isin(exact[k], found[k]).sum() for k in counted)
        recall.append(hits / total)
        print(f"active={b}: recall {recall[-1]:.3f} ({hits} of {total} exact contacts)")

    fig, ax = plt.subplots(figsize=(7, 4), dpi=110)
    ax.semilogx(budgets, recall, "o-")
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("budget: pairs kept per pair type (stochastic `active`)")
    ax.set_ylabel("recall of the exact contacts")
    ax.set_title(f"{sim.scene}, frames {counted[0]}-{counted[-1]}, {args.variant}")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(args.out)
    print(f"-> {args.out}")


if __name__ == "__main__":
    main()
