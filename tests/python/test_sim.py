"""Simulation and rendering from Python against the CLI's `simulate` and `render`, the arrays
they give, errors and the GIL."""

import re
import subprocess
import warnings

import numpy as np
import pytest

import crumple
from conftest import probes_refused_during, run_cli

SPHERE = "cloth-on-sphere:n=8"


def test_scene_run_same_positions_as_cli_simulate(tmp_path, cli):
    run_cli(cli, "simulate", SPHERE, "--frames", 3, "--out", tmp_path / "run", "--format", "ply",
            "--threads", 2, "--quiet")
    s = crumple.Simulation(SPHERE, threads=2)
    assert s.scene == SPHERE and s.frame == 0 and s.num_vertices == 81
    np.testing.assert_array_equal(s.positions,
                                  crumple.read_mesh(tmp_path / "run/frames/000000.ply").vertices)
    stats = s.run(3)
    assert s.frame == 3 and s.time == pytest.approx(3 * s.settings["dt"] * s.settings["substeps"])
    np.testing.assert_array_equal(s.positions,
                                  crumple.read_mesh(tmp_path / "run/frames/000003.ply").vertices)
    np.testing.assert_array_equal(stats["frame"], [1, 2, 3])
    assert stats["vf"].dtype == np.int64 and stats["energy"].dtype == np.float64
    for key in ("retries", "proximity_pairs", "flat_pairs", "motion_pairs", "motion_vertices"):
        assert stats[key].dtype == np.int64 and (stats[key] >= 0).all(), key
    assert stats["bounds_min"].shape == (3, 3) and stats["bounds_max"].shape == (3, 3)
    np.testing.assert_array_equal(stats["bounds_min"][-1], s.positions.min(axis=0))
    csv = (tmp_path / "run/stats.csv").read_text().splitlines()
    header = csv[0].split(",")
    last = dict(zip(header, csv[-1].split(",")))
    assert int(last["frame"]) == 3
    for key in ("vf", "ee", "cg_iterations", "corrections", "ccd_impacts", "ccd_frozen", "ccd_zone_vertices"):
        assert int(last[key]) == stats[key][-1], key
    for key in ("energy", "longest_spring"):
        assert float(last[key]) == pytest.approx(stats[key][-1], rel=1e-8), key  # 9 digits
    assert stats["longest_spring"].dtype == np.float64 and (stats["longest_spring"] > 0).all()


def test_arrays_and_settings():
    s = crumple.Simulation(SPHERE, seed=3, threads=1, response=False, passes=2, substeps=4)
    assert s.settings["response"] is False and s.settings["passes"] == 2
    assert s.settings["substeps"] == 4 and s.settings["threads"] == 1
    x = s.positions
    assert x.shape == (81, 3) and x.dtype == np.float64 and x.flags.writeable
    x[:] = 0  # a copy: the simulation is unaffected
    assert np.abs(s.positions).max() > 0
    assert s.velocities.shape == (81, 3)
    f = s.faces
    assert f.shape == (128, 3) and f.dtype == np.int32 and not f.flags.writeable
    assert s.pinned.shape == (81,) and s.pinned.dtype == np.bool_ and not s.pinned.any()
    one = s.advance()
    assert one["frame"] == 1 and set(one) == set(s.current_stats())
    empty = s.run(0)
    assert s.settings["fail_safe"] is True
    assert empty["frame"].shape == (0,) and empty["bounds_min"].shape == (0, 3)
    # Seeds perturb the scene; the same seed gives the same bits.
    a, b = crumple.Simulation(SPHERE, seed=3), crumple.Simulation(SPHERE, seed=4)
    assert not np.array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.positions, crumple.Simulation(SPHERE, seed=3).positions)


def grid(n):
    """An n x n vertex square of side 0.1 (n-1) in the y = 0 plane: (vertices, faces)."""
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    vertices = np.stack([ii.ravel() * 0.1, np.zeros(n * n), jj.ravel() * 0.1], axis=1)
    quads = [(i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1)
             for i in range(n - 1) for j in range(n - 1)]
    return vertices, np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])


def test_cloth_from_arrays_hangs_from_its_pins():
    n = 5
    vertices, faces = grid(n)
    vertices = vertices.astype(np.float32)
    s = crumple.Simulation.from_mesh(crumple.TriMesh(vertices, faces), "pins=0;4")
    pinned = s.pinned
    assert pinned.sum() == 2 and pinned[0] and pinned[4]
    before = s.positions
    s.run(5)
    after = s.positions
    np.testing.assert_array_equal(after[pinned], before[pinned])
    assert (after[~pinned, 1] < before[~pinned, 1]).all()  # the rest falls
    np.testing.assert_array_equal(s.faces, faces)


def test_cloth_from_a_mesh_same_positions_as_cli_simulate_of_its_file(tmp_path, cli):
    mesh = crumple.TriMesh(*grid(6))
    crumple.write_mesh(tmp_path / "c.ply", mesh)
    run_cli(cli, "simulate", tmp_path / "c.ply", "--param", "pins=0;5", "--param", "stiffness=300",
            "--frames", 4, "--out", tmp_path / "run", "--format", "ply", "--threads", 2, "--quiet")
    s = crumple.Simulation.from_mesh(mesh, "pins=0;5,stiffness=300", threads=2)
    s.run(4)
    np.testing.assert_array_equal(s.positions,
                                  crumple.read_mesh(tmp_path / "run/frames/000004.ply").vertices)


def test_contacts_match_a_detector_on_the_same_positions():
    s = crumple.Simulation("hanging-cloth:nx=10,ny=10", threads=2)
    s.run(50)
    c = s.contacts()
    assert len(c.vf) > 0 and len(c.ee) > 0
    det = crumple.Detector(s.settings["method"], thickness=s.settings["thickness"], threads=2)
    mesh = s.mesh()
    det.set_topology(mesh)
    ref = det.update(mesh.vertices)
    np.testing.assert_array_equal(c.vf.vertex, ref.vf.vertex)
    np.testing.assert_array_equal(c.vf.distance, ref.vf.distance)
    np.testing.assert_array_equal(c.ee.vertices, ref.ee.vertices)
    assert s.current_stats()["vf"] == len(c.vf)


@pytest.mark.parametrize("flags,kwargs", [
    ((), {}),
    (("--wireframe", "--camera", "60,10,4", "--aa", 1), {"wireframe": True, "yaw": 60.0, "pitch": 10.0,
                                                         "distance": 4.0, "supersample": 1}),
    (("--springs",), {"springs": True}),
])
def test_render_same_pixels_as_cli_render(tmp_path, cli, flags, kwargs):
    image = pytest.importorskip("PIL.Image")  # a dependency of Debian's python3-matplotlib
    run_cli(cli, "render", SPHERE, "--frame", 2, "--out", tmp_path / "r.png", "--size", "80x60",
            "--threads", 2, "--quiet", *flags)
    s = crumple.Simulation(SPHERE, threads=2)
    s.run(2)
    picture = s.render(80, 60, **kwargs)
    assert picture.shape == (60, 80, 3) and picture.dtype == np.uint8
    assert picture.base is not None  # owns the rasteriser's pixels through a capsule
    np.testing.assert_array_equal(picture, np.asarray(image.open(tmp_path / "r.png").convert("RGB")))


def test_render_a_mesh_with_its_contacts(data):
    m = crumple.read_mesh(data / "ipc-toolkit-tests/two-cubes-intersecting.ply")
    det = crumple.Detector("kdop", thickness=crumple.default_thickness(m.vertices), kinds="vf,ee,tt")
    det.set_topology(m)
    c = det.update(m.vertices)
    plain = crumple.render(m, width=60, height=40)
    marked = crumple.render(m, m.vertices.astype(np.float32), c, 60, 40, yaw=10, pitch=-30)
    assert plain.shape == marked.shape == (40, 60, 3)
    red = lambda p: ((p[..., 0] >= 160) & (p[..., 1] <= 100) & (p[..., 2] <= 100)).sum()  # noqa: E731
    assert red(plain) == 0 and len(c.vf) + len(c.ee) > 0 and red(marked) > 0
    with pytest.raises(ValueError, match="rows"):
        crumple.render(m, m.vertices[:-1])


@pytest.mark.parametrize("args,kwargs,error,match", [
    (("no-such-scene",), {}, crumple.InputError, "hanging-cloth"),
    (("cloth-on-sphere:m=3",), {}, crumple.InputError, "n"),
    (("cloth-on-sphere:n=abc",), {}, crumple.InputError, "n"),
    ((SPHERE,), {"integrator": "leapfrog"}, crumple.InputError, "implicit-euler"),
    ((SPHERE,), {"method": "nope"}, crumple.InputError, "kdop"),
    ((SPHERE,), {"dt": 0.0}, crumple.InputError, "dt"),
    ((SPHERE,), {"substeps": 0}, crumple.InputError, "substeps"),
    ((SPHERE,), {"thickness": -1.0}, crumple.InputError, "thickness"),
    ((SPHERE,), {"frames": 3}, TypeError, "frames"),
])
def test_bad_scene_and_settings(args, kwargs, error, match):
    with pytest.raises(error, match=match):
        crumple.Simulation(*args, **kwargs)


def test_bad_calls():
    assert issubclass(crumple.InputError, ValueError)
    s = crumple.Simulation(SPHERE)
    with pytest.raises(ValueError, match="frames"):
        s.run(-1)
    for kwargs, match in [({"width": 0}, "width"), ({"supersample": 5}, "supersample"),
                          ({"pitch": 95.0}, "pitch"), ({"distance": -1.0}, "distance")]:
        with pytest.raises(crumple.InputError, match=match):
            s.render(**kwargs)
    with pytest.raises(crumple.InputError, match="pin 999 out of range"):
        crumple.Simulation.from_mesh(s.mesh(), "pins=999")
    with pytest.raises(crumple.InputError, match="nx"):
        crumple.Simulation.from_mesh(s.mesh(), "nx=3")


def test_divergence_error_keeps_the_last_good_frame():
    with pytest.warns(RuntimeWarning, match="stable range"):
        s = crumple.Simulation("hanging-cloth:nx=4,ny=4", integrator="explicit-euler", dt=0.05,
                               substeps=1)
    with pytest.raises(crumple.DivergenceError) as caught:
        s.run(100)
    e = caught.value
    assert isinstance(e, crumple.Error) and e.step == 1 and e.frame == s.frame + 1
    assert "diverged" in e.message and np.isfinite(s.positions).all()


def test_gil_released_while_stepping():
    s = crumple.Simulation("hanging-cloth:nx=16,ny=16", threads=1)
    refused = probes_refused_during(lambda: s.positions, lambda: s.run(10))
    assert refused >= 100, refused


def test_gil_released_while_drawing():
    s = crumple.Simulation(SPHERE, threads=1)
    refused = probes_refused_during(lambda: s.frame, lambda: s.render(400, 300))
    assert refused >= 100, refused


def test_scenes_lists_every_scene_and_its_keys():
    names = [d["name"] for d in crumple.scenes()]
    assert names[-1] == "file" and "cloth-on-sphere" in names
    sphere = next(d for d in crumple.scenes() if d["name"] == "cloth-on-sphere")
    assert sphere["params"]["n"][0] == "16" and sphere["summary"]


def test_fail_safe_setting_and_its_figures():
    """The continuous fail-safe is on by default with response; off, it runs no query."""
    on = crumple.Simulation(SPHERE, threads=1)
    off = crumple.Simulation(SPHERE, threads=1, fail_safe=False)
    assert on.settings["fail_safe"] is True and off.settings["fail_safe"] is False
    a, b = on.run(3), off.run(3)
    assert (a["ccd_queries"] >= 1).all() and a["ccd_ms"].dtype == np.float64
    assert (b["ccd_queries"] == 0).all() and (b["ccd_frozen"] == 0).all()
    assert a["ccd_frozen"].dtype == np.int64
    assert a["ccd_first_restricted"].dtype == np.bool_ and not b["ccd_first_restricted"].any()


def test_motion_settings_follow_the_scene_unless_given():
    """crumple retries a frame up to twice by default; the keywords override the scene's motion settings."""
    assert crumple.Simulation("crumple:n=6", threads=1).settings["motion_retries"] == 2
    assert crumple.Simulation("cloth-on-sphere:n=6", threads=1).settings["motion_retries"] == 0
    s = crumple.Simulation("crumple:n=6", threads=1, motion_retries=0, motion_search=True)
    assert s.settings["motion_retries"] == 0 and s.settings["motion_search"] is True
    with pytest.raises(crumple.InputError, match="motion_retries"):
        crumple.Simulation("crumple:n=6", threads=1, motion_retries=-1)
    assert crumple.Simulation("crumple:n=6", threads=1).settings["untangle_pull"] == "after"
    assert crumple.Simulation("hanging-cloth:nx=4,ny=4", threads=1, untangle_pull="solve").settings["untangle_pull"] == "solve"
    with pytest.raises(crumple.InputError, match="untangle_pull"):
        crumple.Simulation("crumple:n=6", threads=1, untangle_pull="inside")
    assert crumple.Simulation("crumple:n=6", threads=1).settings["push_relaxation"] == 0.5
    assert crumple.Simulation("cloth-on-sphere:n=6", threads=1).settings["push_relaxation"] == 1
    assert crumple.Simulation("crumple:n=6", threads=1, push_relaxation=0.25).settings["push_relaxation"] == 0.25
    for bad in (0, 1.5, float("nan")):
        with pytest.raises(crumple.InputError, match="push_relaxation"):
            crumple.Simulation("crumple:n=6", threads=1, push_relaxation=bad)


def test_fail_safe_first_query_restricted_by_an_exact_detection_only():
    """A resting crumple pile's first fail-safe query is restricted by the start's exact
    detection; a stochastic detection (which may miss pairs) never restricts it."""
    exact = crumple.Simulation("crumple:n=12", threads=1, method="kdop").run(40)
    stochastic = crumple.Simulation("crumple:n=12", threads=1, method="stochastic").run(40)
    assert exact["ccd_first_restricted"].any()
    assert not stochastic["ccd_first_restricted"].any()


def read_stats_csv(path):
    """stats.csv as {column: list of str}, one entry per frame line (frame 0 first)."""
    header, *rows = path.read_text().splitlines()
    names = header.split(",")
    return {name: [row.split(",")[k] for row in rows] for k, name in enumerate(names)}


def test_scene_step_split_for_an_explicit_integrator_as_the_cli(tmp_path, cli):
    """The scene's own step beyond symplectic Euler's stable range is split into the CLI's
    substeps (sim::fit_time_step, shared): the same substeps and the same positions."""
    done = subprocess.run([str(cli), "simulate", "cloth-on-sphere:n=6", "-i", "symplectic-euler",
                           "-n", "5", "--format", "ply", "--threads", "2", "-q",
                           "-o", str(tmp_path / "run")], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    said = re.search(r"using (\d+) substeps of", done.stderr)
    assert said, done.stderr
    s = crumple.Simulation("cloth-on-sphere:n=6", integrator="symplectic-euler", threads=2)
    fit = s.time_step_fit
    assert fit["action"] == "split" and fit["substeps"] == int(said.group(1)) > fit["given_substeps"]
    assert fit["dt"] < fit["stable_dt"] < fit["given_dt"]
    assert s.settings["substeps"] == fit["substeps"] and s.settings["dt"] == fit["dt"]
    assert fit["dt"] * fit["substeps"] == pytest.approx(fit["given_dt"] * fit["given_substeps"])
    s.run(5)
    np.testing.assert_array_equal(s.positions,
                                  crumple.read_mesh(tmp_path / "run/frames/000005.ply").vertices)
    # Implicit Euler is unconditionally stable: the scene's step as it is.
    implicit = crumple.Simulation("cloth-on-sphere:n=6").time_step_fit
    assert implicit["action"] == "stable" and implicit["stable_dt"] == float("inf")


def test_a_given_step_beyond_the_stable_range_is_kept_with_a_warning():
    with pytest.warns(RuntimeWarning, match=r"beyond explicit-euler's stable range.*substeps="):
        s = crumple.Simulation("hanging-cloth:nx=4,ny=4", integrator="explicit-euler", dt=0.01)
    assert s.time_step_fit["action"] == "kept" and s.settings["dt"] == 0.01
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a stable given step: no warning
        s = crumple.Simulation("hanging-cloth:nx=4,ny=4", integrator="explicit-euler", dt=1e-5)
    assert s.time_step_fit["action"] == "stable" and s.settings["dt"] == 1e-5


def test_untangle_figures_same_as_cli_stats(tmp_path, cli):
    """response_from and untangle as the CLI's --response-from and --untangle: the 8x8 hanging
    cloth falls through itself until frame 200, then untangles; the per-frame figures
    intersecting_pairs, pinches, contours and untangle_pulls are the CLI's stats.csv columns."""
    scene, start, frames = "hanging-cloth:nx=8,ny=8", 200, 225
    run_cli(cli, "simulate", scene, "--response-from", start, "--untangle", "on", "--frames", frames,
            "--every", 1000, "--threads", 2, "-q", "-o", tmp_path / "on")
    expected = read_stats_csv(tmp_path / "on/stats.csv")
    s = crumple.Simulation(scene, response_from=start, untangle=True, threads=2)
    assert s.settings["response"] is False and s.settings["response_from"] == start
    stats = s.run(frames)
    assert s.settings["response"] is True and s.settings["response_from"] is None
    assert s.settings["untangle"] is True
    for key in ("intersecting_pairs", "pinches", "contours", "untangle_pulls", "vf", "ee", "ccd_frozen"):
        assert stats[key].dtype == np.int64, key
        np.testing.assert_array_equal(stats[key], np.array(expected[key][1:], dtype=np.int64), key)
    np.testing.assert_allclose(stats["energy"], np.array(expected["energy"][1:], dtype=float), rtol=1e-8)
    pairs = stats["intersecting_pairs"]
    assert (pairs[:start] == -1).all()            # no response: not measured
    assert pairs[start] > 0 and stats["untangle_pulls"][start] > 0  # tangled, then pushed
    assert pairs[-1] == 0 and stats["pinches"][-1] == 0  # untangled, pinches included
    assert stats["untangle_ms"].dtype == np.float64
    # Untangling off: nothing measured.
    off = crumple.Simulation(scene, response_from=start, untangle=False, threads=2).run(start + 3)
    assert (off["intersecting_pairs"] == -1).all() and (off["untangle_pulls"] == 0).all()
    assert (off["pinches"] == -1).all()


@pytest.mark.parametrize("kwargs,match", [
    ({"response_from": -1}, "response_from must be >= 0"),
    ({"response_from": 3, "response": False}, "response_from needs the response on"),
])
def test_bad_response_from(kwargs, match):
    with pytest.raises(crumple.InputError, match=match):
        crumple.Simulation("hanging-cloth:nx=4,ny=4", **kwargs)
