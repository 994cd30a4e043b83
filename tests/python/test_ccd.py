"""Continuous collision detection from Python against the CLI's `crumple ccd` on a real frame
pair, determinism across methods and threads, array handling, zero-copy promises, errors and
the GIL."""

import json

import numpy as np
import pytest

import crumple
from conftest import probes_refused_during, run_cli

FUNNEL = ["sample-scalable-ccd/cloth-funnel/frames/227.ply",
          "sample-scalable-ccd/cloth-funnel/frames/228.ply"]


@pytest.fixture(scope="module")
def funnel(data):
    m0, m1 = (crumple.read_mesh(data / p) for p in FUNNEL)
    x0, x1 = m0.vertices, m1.vertices
    delta = 1e-3 * float(np.linalg.norm(x0.max(axis=0) - x0.min(axis=0)))
    return m0, x0, x1, delta


def parse_impacts(text):
    vf, ee = [], []
    for line in text.splitlines():
        kind, *rest = line.split()
        {"vf": vf, "ee": ee}[kind].append([float(v) for v in rest])
    return np.array(vf).reshape(-1, 9), np.array(ee).reshape(-1, 10)


def test_funnel_impacts_same_as_cli(tmp_path, cli, data, funnel):
    mesh, x0, x1, delta = funnel
    cli_file = tmp_path / "cli.txt"
    report = json.loads(run_cli(cli, "ccd", *(data / p for p in FUNNEL), "--min-separation", repr(delta),
                                "--threads", 2, "--impacts", cli_file, "--json"))
    q = crumple.ContinuousQuery(mesh, min_separation=delta, threads=2)
    impacts = q.query(x0, x1)
    # The same text (17 significant digits: bit-identical times, coordinates and normals) ...
    mine = tmp_path / "mine.txt"
    impacts.write(mine)
    text = cli_file.read_text()
    assert mine.read_text() == text
    # ... the arrays say the same as that text ...
    vf, ee = parse_impacts(text)
    assert (len(impacts.vf), len(impacts.ee)) == (report["vf_impacts"], report["ee_impacts"]) == (len(vf), len(ee))
    assert len(impacts.vf) > 1000 and len(impacts.ee) > 1000  # a real workload
    np.testing.assert_array_equal(impacts.vf.vertex, vf[:, 0])
    np.testing.assert_array_equal(impacts.vf.face, vf[:, 1])
    np.testing.assert_array_equal(impacts.vf.toi, vf[:, 2])
    np.testing.assert_array_equal(impacts.vf.barycentric, vf[:, 3:6])
    np.testing.assert_array_equal(impacts.vf.normal, vf[:, 6:9])
    np.testing.assert_array_equal(impacts.ee.vertices.reshape(-1, 4), ee[:, :4])
    np.testing.assert_array_equal(impacts.ee.toi, ee[:, 4])
    np.testing.assert_array_equal(impacts.ee.s, ee[:, 5])
    np.testing.assert_array_equal(impacts.ee.t, ee[:, 6])
    np.testing.assert_array_equal(impacts.ee.normal, ee[:, 7:10])
    # ... and the step, the counters and the edge ids agree with the CLI and the mesh.
    assert impacts.collision_free_step == report["earliest_toi"]
    assert q.stats["candidates"] == report["stats"]["candidates"]
    assert q.stats["conservative_hits"] == report["stats"]["conservative_hits"]
    np.testing.assert_array_equal(mesh.edges[impacts.ee.edges].reshape(-1, 4), ee[:, :4])
    assert q.min_separation == delta and q.method == "kdop" and q.threads == 2


def test_one_shot_functions_methods_and_threads_agree(funnel):
    mesh, x0, x1, _ = funnel
    base = crumple.continuous_impacts(mesh, x0, x1, threads=2)
    assert len(base) > 0
    for method, threads in [("hash", 2), ("sap:axis=y", 1), ("kdop", 1)]:
        other = crumple.continuous_impacts(mesh, x0, x1, method=method, threads=threads)
        for a, b in [(base.vf.vertex, other.vf.vertex), (base.vf.face, other.vf.face), (base.vf.toi, other.vf.toi),
                     (base.ee.edges, other.ee.edges), (base.ee.toi, other.ee.toi),
                     (base.ee.normal, other.ee.normal)]:
            np.testing.assert_array_equal(a, b, err_msg=method)
    step = crumple.collision_free_step(mesh, x0, x1, threads=2)
    assert step == base.collision_free_step
    assert step == min(base.vf.toi.min(initial=1.0), base.ee.toi.min(initial=1.0))
    # No motion and no separation asked: nothing comes closer than it is, and a pair already
    # touching would be reported at 0; the full step otherwise.
    still = crumple.continuous_impacts(mesh, x1, x1)
    assert still.collision_free_step in (0.0, 1.0)
    names = crumple.ccd_outcomes()
    assert names[0] == "separated-hull" and "hit-tolerance" in names
    used = {names[o] for o in np.concatenate([base.vf.outcome, base.ee.outcome])}
    assert used and all(n.startswith("hit-") for n in used)


def test_positions_dtypes_layouts_and_zero_copy(funnel):
    mesh, x0, x1, delta = funnel
    q = crumple.ContinuousQuery(mesh, min_separation=delta, threads=2)
    a = q.query(x0, x1)
    assert not q.last_positions_copied  # float64 C-contiguous: read in place
    # Arrays are read-only views over the library's records (no copy), kept valid after the
    # next query, which then fills another buffer.
    toi = a.vf.toi
    assert not toi.flags.writeable and not toi.flags.owndata
    assert toi.dtype == np.float64 and a.vf.vertex.dtype == np.int32 and a.ee.outcome.dtype == np.uint8
    assert a.vf.barycentric.shape == (len(a.vf), 3) and a.ee.vertices.shape == (len(a.ee), 2, 2)
    assert np.may_share_memory(a.vf.vertex, a.vf.toi)  # columns of the same records
    assert toi.strides == a.vf.vertex.strides and toi.strides[0] >= 64  # at the record's stride
    kept = toi.copy()
    b = q.query(x1, x1)
    np.testing.assert_array_equal(toi, kept)
    assert len(b.vf) != len(a.vf) or not np.shares_memory(b.vf.toi, toi)
    # float32 positions: converted once, the impacts of float64 positions made from the floats.
    f0, f1 = x0.astype(np.float32), x1.astype(np.float32)
    c32 = q.query(f0, f1)
    assert q.last_positions_copied
    c64 = q.query(f0.astype(np.float64), f1.astype(np.float64))
    np.testing.assert_array_equal(c32.ee.toi, c64.ee.toi)
    np.testing.assert_array_equal(c32.vf.face, c64.vf.face)
    # A strided view and a list are accepted too.
    wide = np.zeros((len(x0), 8))
    wide[:, :3] = x0
    np.testing.assert_array_equal(q.query(wide[:, :3], x1.tolist()).vf.toi, a.vf.toi)


def test_errors(funnel):
    mesh, x0, x1, _ = funnel
    q = crumple.ContinuousQuery(mesh)
    with pytest.raises(ValueError, match="shape"):
        q.query(x0[:, :2], x1)
    with pytest.raises(ValueError, match="rows"):
        q.query(x0[:-1], x1[:-1])
    bad = x1.copy()
    bad[5, 1] = np.nan
    with pytest.raises(crumple.InputError):
        q.query(x0, bad)
    with pytest.raises(crumple.InputError):
        crumple.ContinuousQuery(mesh, method="naive")
    with pytest.raises(crumple.InputError):
        crumple.ContinuousQuery(mesh, min_separation=-1.0)
    with pytest.raises(crumple.InputError):
        crumple.ContinuousQuery(mesh, max_boxes=0)
    with pytest.raises(ValueError, match="rows"):
        crumple.collision_free_step(mesh, x0[:-1], x1[:-1])
    with pytest.raises(TypeError):
        crumple.ContinuousQuery(mesh, 0.1)  # the options are keywords


def test_query_releases_the_gil(funnel):
    mesh, x0, x1, delta = funnel
    q = crumple.ContinuousQuery(mesh, min_separation=delta, threads=1)
    refused = probes_refused_during(lambda: q.stats, lambda: [q.query(x0, x1) for _ in range(2)])
    assert refused > 0
