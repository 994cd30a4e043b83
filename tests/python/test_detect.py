"""Detection from Python against the CLI's results on the shared real meshes, array handling,
zero-copy promises, errors, state and the GIL."""

import threading
import tracemalloc

import numpy as np
import pytest

import crumple
from conftest import probes_refused_during, run_cli

FUNNEL = ["sample-scalable-ccd/cloth-funnel/frames/227.ply",
          "sample-scalable-ccd/cloth-funnel/frames/228.ply"]
ARMADILLO = ["sample-scalable-ccd/armadillo-rollers/frames/326.ply",
             "sample-scalable-ccd/armadillo-rollers/frames/327.ply"]
CUBES = "ipc-toolkit-tests/two-cubes-intersecting.ply"


def detect_frames(paths, method, kinds="vf,ee", threads=2):
    """What `crumple detect FILES --method M` does, from Python: one detector, each frame after
    the first with the previous positions."""
    meshes = [crumple.read_mesh(p) for p in paths]
    det = crumple.Detector(method, thickness=crumple.default_thickness(meshes[0].vertices),
                           kinds=kinds, threads=threads)
    det.set_topology(meshes[0])
    out, previous = [], None
    for m in meshes:
        out.append(det.update(m.vertices) if previous is None else det.update(previous, m.vertices))
        previous = m.vertices
    return det, out


def parse_contacts(text):
    vf, ee, tt = [], [], []
    for line in text.splitlines():
        kind, *rest = line.split()
        {"vf": vf, "ee": ee, "tt": tt}[kind].append(rest)
    return vf, ee, tt


def check_same_as_cli(tmp_path, cli, paths, method, kinds="vf,ee"):
    det, results = detect_frames(paths, method, kinds)
    outdir = tmp_path / "cli"
    run_cli(cli, "detect", *paths, "--method", method, "--kinds", kinds, "--threads", 2,
            "--contacts", outdir if len(paths) > 1 else outdir.with_suffix(".tsv"))
    for path, c in zip(paths, results):
        expected = (outdir / (path.stem + ".tsv")) if len(paths) > 1 else outdir.with_suffix(".tsv")
        text = expected.read_text()
        # The same text (17 significant digits: bit-identical distances) ...
        mine = tmp_path / "mine.tsv"
        c.write(mine)
        assert mine.read_text() == text, f"{method} {path.name}"
        # ... and the arrays say the same as that text.
        vf, ee, tt = parse_contacts(text)
        assert (len(c.vf), len(c.ee), len(c.tt)) == (len(vf), len(ee), len(tt))
        if vf:
            vf = np.array(vf, dtype=float)
            np.testing.assert_array_equal(c.vf.vertex, vf[:, 0])
            np.testing.assert_array_equal(c.vf.face, vf[:, 1])
            np.testing.assert_array_equal(c.vf.distance, vf[:, 2])
        if ee:
            ee = np.array(ee, dtype=float)
            np.testing.assert_array_equal(c.ee.vertices.reshape(-1, 4), ee[:, :4])
            np.testing.assert_array_equal(c.ee.distance, ee[:, 4])
        if tt:
            np.testing.assert_array_equal(c.tt.faces, np.array(tt, dtype=int))
    return det, results


def test_kdop_funnel_two_frames_same_as_cli(tmp_path, cli, data):
    det, (c0, c1) = check_same_as_cli(tmp_path, cli, [data / p for p in FUNNEL], "kdop")
    assert len(c0.vf) > 1000 and len(c1.ee) > 1000  # a real workload, not an empty set
    assert det.stats["candidates"] > 0
    assert det.last_update_ms > 0  # the library call alone, as the CLI's --json "ms"


@pytest.mark.parametrize("method", ["hash", "sap:axis=y"])
def test_other_exact_methods_armadillo_same_as_cli(tmp_path, cli, data, method):
    check_same_as_cli(tmp_path, cli, [data / p for p in ARMADILLO], method)


def test_stochastic_spec_with_keys_same_as_cli(tmp_path, cli, data):
    check_same_as_cli(tmp_path, cli, [data / p for p in FUNNEL],
                      "stochastic:variant=vertex,active=50,seed=7")


@pytest.mark.parametrize("method", [m["name"] for m in crumple.methods()])
def test_every_method_with_tt_same_as_cli(tmp_path, cli, data, method):
    _, (c,) = check_same_as_cli(tmp_path, cli, [data / CUBES], method, kinds="vf,ee,tt")
    if method != "stochastic":
        assert len(c.tt) > 0


def spec_with_every_key(method):
    """NAME:key=default,... with every key the method accepts (crumple.methods())."""
    return method["name"] + ":" + ",".join(f"{k}={v[0]}" for k, v in method["params"].items())


@pytest.mark.parametrize("method", [m for m in crumple.methods() if m["params"]],
                         ids=lambda m: m["name"])
def test_every_key_of_every_method_same_as_cli(tmp_path, cli, data, method):
    det, _ = check_same_as_cli(tmp_path, cli, [data / CUBES], spec_with_every_key(method),
                               kinds="vf,ee,tt")
    assert det.method.split(":")[0] == method["name"]


@pytest.mark.parametrize("spec", [
    "hybrid:leaf=32,every=2,zones=6,search=stochastic,draw=20,propagation=full,near=3,steps=4,seed=9",
    "hybrid:search=exact,leaf=16,propagation=none",
    "stochastic:variant=propagate-by-convergence,active=30,draw=10,propagation=full,near=3,"
    "steps=8,ef=on,seed=5",
    "stochastic:setting=1,seed=2",
    "kdop:k=26,arity=2,leaf=16,rebuild=1,sweep=on,cones=on,coherence=off",
    "hash:cell=0.02,table=4096",
])
def test_non_default_keys_two_frames_same_as_cli(tmp_path, cli, data, spec):
    """Stochastic and hybrid detectors carry state across frames: the second frame's contacts
    depend on it, and are the CLI's."""
    det, _ = check_same_as_cli(tmp_path, cli, [data / p for p in FUNNEL], spec)
    assert det.method.split(":")[0] == spec.split(":")[0]


def test_relative_thickness_is_the_clis_thickness_rel(tmp_path, cli, data):
    m = crumple.read_mesh(data / CUBES)
    h = crumple.default_thickness(m.vertices, relative=0.05)
    diagonal = np.linalg.norm(m.vertices.max(axis=0) - m.vertices.min(axis=0))
    assert h == pytest.approx(0.05 * diagonal, rel=1e-15)
    assert crumple.default_thickness(m.vertices, relative=1e-3) == crumple.default_thickness(m.vertices)
    det = crumple.Detector("kdop", thickness=h, kinds="vf,ee,tt")
    det.set_topology(m)
    run_cli(cli, "detect", data / CUBES, "-r", 0.05, "-k", "vf,ee,tt", "--contacts", tmp_path / "cli.tsv")
    det.update(m.vertices).write(tmp_path / "mine.tsv")
    assert (tmp_path / "mine.tsv").read_text() == (tmp_path / "cli.tsv").read_text()
    with pytest.raises(crumple.InputError, match="relative"):
        crumple.default_thickness(m.vertices, relative=-1.0)


def test_geometry_of_the_arrays(data):
    m = crumple.read_mesh(data / FUNNEL[0])
    _, (c,) = detect_frames([data / FUNNEL[0]], "kdop")
    x = m.vertices
    h = crumple.default_thickness(x)
    # VF: the closest point from the barycentrics, the distance and the normal agree.
    corners = x[m.faces[c.vf.face]]                         # (k, 3, 3)
    closest = np.einsum("kc,kcd->kd", c.vf.barycentric, corners)
    d = x[c.vf.vertex] - closest
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), c.vf.distance, rtol=1e-9, atol=1e-12)
    assert np.all(c.vf.distance < h)
    np.testing.assert_allclose(c.vf.barycentric.sum(axis=1), 1.0, atol=1e-12)
    # EE: edge ids and vertex ids agree; the closest points are distance apart.
    np.testing.assert_array_equal(m.edges[c.ee.edges], c.ee.vertices)
    a = c.ee.vertices[:, 0]
    b = c.ee.vertices[:, 1]
    pa = (1 - c.ee.s)[:, None] * x[a[:, 0]] + c.ee.s[:, None] * x[a[:, 1]]
    pb = (1 - c.ee.t)[:, None] * x[b[:, 0]] + c.ee.t[:, None] * x[b[:, 1]]
    np.testing.assert_allclose(np.linalg.norm(pb - pa, axis=1), c.ee.distance, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(c.ee.normal, axis=1)[c.ee.distance > 0], 1.0, atol=1e-12)


def test_results_are_views_over_the_records(data):
    m = crumple.read_mesh(data / FUNNEL[0])
    det = crumple.Detector("kdop", thickness=crumple.default_thickness(m.vertices), threads=2)
    det.set_topology(m)
    c = det.update(m.vertices)
    vf, ee = c.vf, c.ee
    # One record per row: every field of row i lies in record i (64 bytes VF, 72 bytes EE).
    assert vf.vertex.strides == (64,) and vf.distance.strides == (64,)
    assert vf.barycentric.strides == (64, 8) and vf.normal.strides == (64, 8)
    assert vf.distance.ctypes.data - vf.vertex.ctypes.data == 8
    assert ee.edges.strides[0] == ee.s.strides[0] == ee.normal.strides[0]
    assert ee.vertices.ctypes.data - ee.edges.ctypes.data == 8
    for arr in (vf.vertex, vf.face, vf.distance, vf.barycentric, vf.normal, ee.edges,
                ee.vertices, ee.s, ee.t, ee.distance, ee.normal):
        assert not arr.flags.owndata and not arr.flags.writeable
    # Reading a field twice gives the same memory, from any view object of the result.
    assert np.shares_memory(c.vf.distance, vf.distance)
    assert np.shares_memory(c.ee.normal, ee.normal)


def test_a_result_survives_later_updates_and_the_buffer_is_reused(data):
    m0, m1 = (crumple.read_mesh(data / p) for p in FUNNEL)
    det = crumple.Detector("kdop", thickness=crumple.default_thickness(m0.vertices), threads=2)
    det.set_topology(m0)
    first = det.update(m0.vertices)
    dist = first.vf.distance
    saved = dist.copy()
    second = det.update(m0.vertices, m1.vertices)
    assert not np.shares_memory(second.vf.distance, dist)  # a live result is never rewritten
    np.testing.assert_array_equal(dist, saved)
    del first, dist
    # No Python reference to the earlier results left: the detector may rewrite those records.
    del second
    third = det.update(m0.vertices)
    np.testing.assert_array_equal(third.vf.distance, saved)


def test_positions_layouts(data):
    m = crumple.read_mesh(data / FUNNEL[0])
    x32 = m.vertices.astype(np.float32)
    x = x32.astype(np.float64)  # the float32 values, exactly
    det = crumple.Detector("kdop", thickness=crumple.default_thickness(x), threads=2)
    det.set_topology(m)
    ref = det.update(x)
    assert det.last_positions_copied is False  # float64 C-contiguous: read in place
    assert det.last_positions_conversion == "none"
    wide = np.zeros((len(x), 5))
    wide[:, 1:4] = x
    engine = np.zeros((len(x), 8), dtype=np.float32)  # position, normal, uv
    engine[:, 0:3] = x32
    unaligned = np.frombuffer(b"\0" * 4 + x.tobytes(), dtype=np.float64, offset=4).reshape(-1, 3)
    assert not unaligned.flags.aligned
    cases = {  # name: (positions, where they become float64)
        "float32": (x32, "detector"),
        "interleaved float32": (engine[:, 0:3], "detector"),
        "strided": (wide[:, 1:4], "detector"),
        "every other row": (np.repeat(x, 2, axis=0)[::2], "detector"),
        "unaligned": (unaligned, "detector"),
        "fortran": (np.asfortranarray(x), "binding"),
        "big-endian": (x.astype(">f8"), "binding"),
        "list": (x.tolist(), "binding"),
    }
    for name, (positions, conversion) in cases.items():
        c = det.update(positions)
        assert det.last_positions_conversion == conversion, name
        assert det.last_positions_copied is (conversion != "none"), name
        for f in ("vertex", "face", "distance", "barycentric", "normal"):
            np.testing.assert_array_equal(getattr(c.vf, f), getattr(ref.vf, f), err_msg=name)
        for f in ("vertices", "s", "t", "distance", "normal"):
            np.testing.assert_array_equal(getattr(c.ee, f), getattr(ref.ee, f), err_msg=name)
    # With motion (kdop uses it): float32 previous and current frames, converted in the detector.
    y32 = (x + 1e-3 * np.sin(np.arange(len(x)))[:, None]).astype(np.float32)
    ref = det.update(x, y32.astype(np.float64))
    c = det.update(x32, y32)
    assert det.last_positions_conversion == "detector"
    np.testing.assert_array_equal(c.vf.distance, ref.vf.distance)
    np.testing.assert_array_equal(c.ee.vertices, ref.ee.vertices)


def test_float32_views_are_not_copied_by_the_binding(data):
    """A float32 interleaved buffer goes to the detector without a NumPy copy: the memory NumPy
    allocates during update (traced) stays far below one float64 copy of the positions."""
    m = crumple.read_mesh(data / FUNNEL[0])
    det = crumple.Detector("kdop", thickness=crumple.default_thickness(m.vertices), threads=2)
    det.set_topology(m)
    engine = np.zeros((m.num_vertices, 8), dtype=np.float32)
    engine[:, 0:3] = m.vertices
    det.update(engine[:, 0:3])  # warm-up: the detector's own buffers
    copy_bytes = m.num_vertices * 3 * 8
    for positions, copied in [(engine[:, 0:3], False), (np.asfortranarray(m.vertices), True)]:
        tracemalloc.start()
        det.update(positions)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert (peak >= copy_bytes) is copied, (peak, copy_bytes)


def test_bad_positions_and_state_errors(data):
    m = crumple.read_mesh(data / CUBES)
    det = crumple.Detector("kdop", thickness=0.01)
    with pytest.raises(RuntimeError, match="set_topology"):
        det.update(m.vertices)
    det.set_topology(m)
    x = np.array(m.vertices)
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        det.update(x[:, :2])
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        det.update(x.ravel())
    with pytest.raises(ValueError, match="rows"):
        det.update(x[:-1])
    with pytest.raises(ValueError, match="previous"):
        det.update(x[:-1], x)
    with pytest.raises(ValueError, match="real dtype"):
        det.update(x.astype(str))
    x[3, 1] = np.inf
    with pytest.raises(crumple.InputError, match="vertex 3"):
        det.update(x)


@pytest.mark.parametrize("args, match", [
    (("octree",), "kdop"),                # lists the valid names
    (("kdop:bogus=1",), "bogus"),
    (("stochastic:active=many",), "active"),
])
def test_bad_method_specs(args, match):
    with pytest.raises(crumple.InputError, match=match):
        crumple.Detector(*args, thickness=0.1)


def test_bad_options():
    with pytest.raises(crumple.InputError):
        crumple.Detector("kdop", thickness=-1.0)
    with pytest.raises(crumple.InputError):
        crumple.Detector("kdop", thickness=0.1, kinds="vf,xx")
    with pytest.raises(crumple.InputError):
        crumple.Detector("kdop", thickness=0.1, threads=-2)
    with pytest.raises(TypeError):
        crumple.Detector("kdop")  # thickness is required, keyword-only
    d = crumple.Detector("sap", thickness=0.5, kinds="ee,tt", threads=1)
    assert (d.method, d.thickness, d.kinds, d.threads) == ("sap", 0.5, "ee,tt", 1)
    assert d.capabilities == {"exact": True, "stochastic": False, "uses_motion": False}


def test_stats_have_the_cli_json_keys(cli, data):
    import json
    path = data / CUBES
    det, _ = detect_frames([path], "kdop")
    line = run_cli(cli, "detect", path, "--method", "kdop", "--threads", 2, "--json")
    assert set(det.stats) == set(json.loads(line)["stats"])


def test_save_and_load_state_replays_the_last_update(data):
    m0, m1 = (crumple.read_mesh(data / p) for p in FUNNEL)
    spec = "stochastic:active=20,seed=3"
    h = crumple.default_thickness(m0.vertices)
    a = crumple.Detector(spec, thickness=h, threads=1)
    a.set_topology(m0)
    a.update(m0.vertices)
    last = a.update(m0.vertices, m1.vertices)
    state = a.save_state()
    assert state
    b = crumple.Detector(spec, thickness=h, threads=1)
    b.set_topology(m0)
    b.load_state(state)
    again = b.update(m0.vertices, m1.vertices)
    np.testing.assert_array_equal(again.vf.vertex, last.vf.vertex)
    np.testing.assert_array_equal(again.ee.vertices, last.ee.vertices)
    exact = crumple.Detector("kdop", thickness=h)
    exact.set_topology(m0)
    assert exact.save_state() == ""
    with pytest.raises(crumple.InputError):
        exact.load_state("junk")
    with pytest.raises(crumple.InputError):
        b.load_state("not a state")


def test_gil_released_during_update(data):
    m = crumple.read_mesh(data / ARMADILLO[0])
    det = crumple.Detector("naive", thickness=crumple.default_thickness(m.vertices), threads=1)
    det.set_topology(crumple.TriMesh(m.vertices[:1200], m.faces[np.all(m.faces < 1200, axis=1)]))
    x = np.ascontiguousarray(m.vertices[:1200])
    # Every probe of another thread refused while the update runs ran during that C++ call.
    refused = probes_refused_during(lambda: det.stats, lambda: det.update(x))
    assert refused >= 100, refused


def test_a_detector_busy_in_another_thread_refuses_other_calls(data):
    m = crumple.read_mesh(data / ARMADILLO[0])
    keep = np.all(m.faces < 1200, axis=1)
    det = crumple.Detector("naive", thickness=crumple.default_thickness(m.vertices), threads=1)
    det.set_topology(crumple.TriMesh(m.vertices[:1200], m.faces[keep]))
    x = np.ascontiguousarray(m.vertices[:1200])
    worker = threading.Thread(target=det.update, args=(x,))
    refused = 0
    worker.start()
    while worker.is_alive():
        try:
            det.stats  # noqa: B018 -- reading it is the check
        except RuntimeError as e:
            assert "in use" in str(e)
            refused += 1
    worker.join()
    assert refused > 0
    assert det.stats  # free again once the update is done
