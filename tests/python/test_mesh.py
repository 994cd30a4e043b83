"""Meshes from Python: construction, validation errors, topology arrays, I/O and error mapping."""

import numpy as np
import pytest

import crumple

FUNNEL = "sample-scalable-ccd/cloth-funnel/frames/227.ply"


def square():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
    f = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)
    return v, f


def test_real_mesh_counts_and_views(data):
    m = crumple.read_mesh(data / FUNNEL)
    assert (m.num_vertices, m.num_faces) == (9450, 18484)  # the data README's figures
    assert m.vertices.shape == (9450, 3) and m.vertices.dtype == np.float64
    assert m.faces.shape == (18484, 3) and m.faces.dtype == np.int32
    assert m.edges.shape == (m.num_edges, 2) and m.edges.dtype == np.int32
    # Views over the mesh's storage: read-only, and two reads are the same memory (a copy each
    # time would not share it).
    for name in ("vertices", "faces", "edges", "face_edges"):
        a, b = getattr(m, name), getattr(m, name)
        assert not a.flags.writeable
        assert np.shares_memory(a, b), name
    with pytest.raises(ValueError):
        m.vertices[0, 0] = 1.0


def test_edges_follow_the_documented_numbering(data):
    m = crumple.read_mesh(data / FUNNEL)
    faces = m.faces.astype(np.int64)
    # First appearance over faces, sides (v0,v1), (v1,v2), (v2,v0), stored (min, max).
    sides = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    sides.sort(axis=1)
    _, first = np.unique(sides, axis=0, return_index=True)
    expected = sides[np.sort(first)]
    np.testing.assert_array_equal(m.edges, expected)
    # face_edges[f, k] is the edge between corners k and (k+1)%3.
    np.testing.assert_array_equal(m.edges[m.face_edges].reshape(-1, 2), sides)


def test_adjacency_csr_matches_edges(data):
    m = crumple.read_mesh(data / FUNNEL)
    offsets, neighbours = m.adjacency("vertex_vertices")
    assert offsets.shape == (m.num_vertices + 1,) and offsets[-1] == len(neighbours)
    assert neighbours.dtype == np.int32 and not neighbours.flags.writeable
    rows = np.repeat(np.arange(m.num_vertices), np.diff(offsets))
    got = np.stack([rows, neighbours], axis=1)
    e = m.edges.astype(np.int64)
    want = np.concatenate([e, e[:, ::-1]])
    want = want[np.lexsort((want[:, 1], want[:, 0]))]
    np.testing.assert_array_equal(got, want)
    offsets, faces = m.adjacency("edge_faces")
    assert offsets.shape == (m.num_edges + 1,)
    assert len(faces) == 3 * m.num_faces  # every face has three edges
    with pytest.raises(ValueError, match="vertex_vertices"):
        m.adjacency("faces_of_nothing")


def test_float32_and_float64_give_the_same_mesh():
    v, f = square()
    a = crumple.TriMesh(v, f)
    b = crumple.TriMesh(v.astype(np.float32), f.astype(np.uint16))
    c = crumple.TriMesh(np.asfortranarray(v), f[:, :])
    for m in (b, c):
        np.testing.assert_array_equal(m.vertices, a.vertices)
        np.testing.assert_array_equal(m.faces, a.faces)
    assert a.report["boundary_edges"] == 4


@pytest.mark.parametrize("vertices, faces, error, match", [
    (np.zeros((4, 2)), np.array([[0, 1, 2]]), ValueError, r"shape \(n, 3\)"),
    (np.zeros(12), np.array([[0, 1, 2]]), ValueError, r"shape \(n, 3\)"),
    (np.zeros((4, 3)), np.array([[0, 1]]), ValueError, r"shape \(m, 3\)"),
    (np.zeros((4, 3)), np.array([[0.0, 1.0, 2.0]]), ValueError, "integer dtype"),
    (np.array([["a", "b", "c"]] * 4), np.array([[0, 1, 2]]), ValueError, "real dtype"),
    (np.zeros((4, 3)), np.array([[0, 1, 2**40]]), ValueError, "32-bit"),
    (np.zeros((4, 3)), np.array([[0, 1, 4]]), crumple.InputError, "face 0"),
    (np.zeros((4, 3)), np.array([[0, 1, 1]]), crumple.InputError, "face 0"),
    (np.array([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]]), np.array([[0, 1, 2]]), crumple.InputError,
     "vertex 2"),
])
def test_invalid_arrays(vertices, faces, error, match):
    with pytest.raises(error, match=match):
        crumple.TriMesh(vertices, faces)


def test_error_hierarchy():
    for e in (crumple.ParseError, crumple.InputError, crumple.PreconditionError):
        assert issubclass(e, crumple.Error) and issubclass(e, ValueError)


def test_malformed_obj_gives_parse_error_with_file_and_line(tmp_path):
    path = tmp_path / "bad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n# fine so far\nv 1 2 oops\nf 1 2 3\n")
    with pytest.raises(crumple.ParseError) as info:
        crumple.read_mesh(path)
    e = info.value
    assert isinstance(e, ValueError)
    assert e.file == str(path) and e.line == 5 and e.byte_offset is None
    assert f"{path}:5:" in str(e) and e.message and e.message in str(e)


def test_missing_file_and_bad_extension(tmp_path):
    with pytest.raises(crumple.ParseError) as info:
        crumple.read_mesh(tmp_path / "none.ply")
    assert info.value.file == str(tmp_path / "none.ply") and info.value.line is None
    with pytest.raises(ValueError, match=r"\.obj"):
        crumple.read_mesh(tmp_path / "mesh.stl")


def test_binary_ply_error_has_byte_offset(tmp_path, data):
    good = (data / "ipc-toolkit-tests/cube.ply").read_bytes()
    path = tmp_path / "short.ply"
    path.write_bytes(good[:-5])
    with pytest.raises(crumple.ParseError) as info:
        crumple.read_mesh(path)
    assert info.value.file == str(path)
    assert info.value.line is not None or info.value.byte_offset is not None


@pytest.mark.parametrize("ext", ["obj", "ply", "off", "x3d"])
def test_write_read_round_trip(tmp_path, data, ext):
    m = crumple.read_mesh(data / "ipc-toolkit-tests/bunny.ply")
    crumple.write_mesh(tmp_path / f"bunny.{ext}", m)
    back = crumple.read_mesh(tmp_path / f"bunny.{ext}")
    np.testing.assert_array_equal(back.vertices, m.vertices)  # bit for bit
    np.testing.assert_array_equal(back.faces, m.faces)


def test_write_to_unwritable_place_is_parse_error(tmp_path):
    v, f = square()
    with pytest.raises(crumple.ParseError):
        crumple.write_mesh(tmp_path / "no" / "such" / "dir" / "m.obj", crumple.TriMesh(v, f))
