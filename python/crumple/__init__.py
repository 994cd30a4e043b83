"""crumple: real-time self-collision detection on deformable triangle meshes.

Five lines, what ``crumple detect`` does::

    import crumple
    mesh = crumple.read_mesh("frame.ply")              # or crumple.TriMesh(vertices, faces)
    det = crumple.Detector("kdop", thickness=crumple.default_thickness(mesh.vertices))
    det.set_topology(mesh)
    contacts = det.update(mesh.vertices)                # contacts.vf.distance, contacts.ee.normal, ...

Arrays going in are read in place when float64 and C-contiguous; arrays coming out are
read-only views over the library's buffers. Errors: crumple.ParseError, crumple.InputError and
crumple.PreconditionError, all subclasses of crumple.Error, a ValueError.
"""

from ._crumple import (  # noqa: F401
    Contacts,
    Detector,
    DivergenceError,
    EdgeEdgeContacts,
    Error,
    InputError,
    ParseError,
    PreconditionError,
    Simulation,
    TriangleTriangleContacts,
    TriMesh,
    VertexFaceContacts,
    default_thickness,
    methods,
    read_mesh,
    render,
    scenes,
    write_mesh,
)

__all__ = [
    "Contacts",
    "Detector",
    "DivergenceError",
    "EdgeEdgeContacts",
    "Error",
    "InputError",
    "ParseError",
    "PreconditionError",
    "Simulation",
    "TriangleTriangleContacts",
    "TriMesh",
    "VertexFaceContacts",
    "default_thickness",
    "methods",
    "read_mesh",
    "render",
    "scenes",
    "write_mesh",
]
