"""Simulate a cloth and save a picture of its last frame beside its per-frame figures.

    PYTHONPATH=build/release/python /usr/bin/python3 examples/python/simulate_cloth.py \
        [--scene cloth-on-sphere:n=32] [--frames 120] [--size 640x480] [--out cloth.png]

The picture is the CLI's `crumple render` of that frame (edges in collision in red); the plot
shows the contacts and the kinetic-plus-potential energy of every frame.
"""

import argparse
import pathlib

import matplotlib

matplotlib.use("Agg")  # writes a file, needs no display
import matplotlib.pyplot as plt  # noqa: E402

import crumple  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="cloth-on-sphere:n=32",
                        help="built-in scene spec, as `crumple simulate` (see crumple.scenes())")
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--size", default="640x480", help="picture WxH in pixels")
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("cloth.png"))
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))

    sim = crumple.Simulation(args.scene, threads=args.threads)
    stats = sim.run(args.frames)  # each figure: one array over the frames
    picture = sim.render(width, height)  # (height, width, 3) uint8

    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.5), dpi=100,
                                      gridspec_kw={"width_ratios": [4, 3]})
    left.imshow(picture)
    left.set_axis_off()
    left.set_title(f"{sim.scene}, frame {sim.frame} (t = {sim.time:.2f} s)")
    right.plot(stats["frame"], stats["vf"] + stats["ee"], label="contacts (vf + ee)")
    right.set_xlabel("frame")
    right.set_ylabel("contacts")
    energy = right.twinx()
    energy.plot(stats["frame"], stats["energy"], color="tab:orange", label="energy (J)")
    energy.set_ylabel("energy (J)")
    right.legend(loc="upper left")
    energy.legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(args.out)
    print(f"{sim}: {int(stats['vf'][-1])} vf + {int(stats['ee'][-1])} ee contacts at the end "
          f"-> {args.out}")


if __name__ == "__main__":
    main()
