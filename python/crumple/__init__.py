"""crumple: real-time self-collision detection on deformable triangle meshes.

Five lines, what ``crumple detect`` does::

    import crumple
    mesh = crumple.read_mesh("frame.ply")              # or crumple.TriMesh(vertices, faces)
    det = crumple.Detector("kdop", thickness=crumple.default_thickness(mesh.vertices))
    det.set_topology(mesh)
    contacts = det.update(mesh.vertices)                # contacts.vf.distance, contacts.ee.normal, ...

Continuous collision detection (the CLI's ``ccd``)::

    impacts = crumple.continuous_impacts(mesh, x0, x1, min_separation=1e-3)   # or ContinuousQuery
    impacts.vf.toi, impacts.ee.edges, impacts.collision_free_step

Simulation and pictures (the CLI's ``simulate`` and ``render``)::

    sim = crumple.Simulation("cloth-on-sphere:n=32")    # crumple.scenes() lists the scenes
    stats = sim.run(100)                                # dict of (100,) arrays per figure
    picture = sim.render(640, 480)                      # (480, 640, 3) uint8

Positions going in are read in place when float64 and C-contiguous, and when float32 or
row-strided converted once inside the detector (no copy by the binding); arrays coming out are
read-only views over the library's buffers. Errors: crumple.ParseError, crumple.InputError,
crumple.PreconditionError and crumple.DivergenceError, all subclasses of crumple.Error, a
ValueError. The GIL is released while detecting, stepping and drawing. See docs/python.md.
"""

from ._crumple import (  # noqa: F401
    Contacts,
    ContinuousQuery,
    Detector,
    DivergenceError,
    EdgeEdgeContacts,
    EdgeEdgeImpacts,
    Error,
    Impacts,
    InputError,
    ParseError,
    PreconditionError,
    Simulation,
    TriangleTriangleContacts,
    TriMesh,
    VertexFaceContacts,
    VertexFaceImpacts,
    ccd_outcomes,
    collision_free_step,
    continuous_impacts,
    default_thickness,
    methods,
    read_mesh,
    render,
    scenes,
    write_mesh,
)

__all__ = [
    "Contacts",
    "ContinuousQuery",
    "Detector",
    "DivergenceError",
    "EdgeEdgeContacts",
    "EdgeEdgeImpacts",
    "Error",
    "Impacts",
    "InputError",
    "ParseError",
    "PreconditionError",
    "Simulation",
    "TriangleTriangleContacts",
    "TriMesh",
    "VertexFaceContacts",
    "VertexFaceImpacts",
    "ccd_outcomes",
    "collision_free_step",
    "continuous_impacts",
    "default_thickness",
    "methods",
    "read_mesh",
    "render",
    "scenes",
    "write_mesh",
]
