"""Type stub of crumple (the extension crumple._crumple). Shapes: n vertices, m faces,
e edges, k contacts of one kind."""

import os
from typing import Any, Sequence, Union, overload

import numpy as np
import numpy.typing as npt

_Path = Union[str, os.PathLike[str]]
_Positions = npt.ArrayLike  # (n, 3) real; float64 C-contiguous is read in place
_Faces = npt.ArrayLike  # (m, 3) integer

class Error(ValueError):
    """Base of every error crumple raises."""

class ParseError(Error):
    """A file that cannot be read or written, or whose content is malformed."""
    file: str
    line: int | None  # 1-based, text formats
    byte_offset: int | None  # binary formats
    message: str  # without the location prefix

class InputError(Error):
    """Invalid input that is not a file (method spec, mesh arrays, thickness, state text)."""

class PreconditionError(Error):
    """A violated library precondition; the message names the library's file and line."""

class DivergenceError(Error):
    """A simulation step diverged; the simulation is back at the start of that frame."""
    frame: int  # the frame being computed
    step: int  # its 1-based step that went bad
    message: str

class TriMesh:
    """Validated, immutable triangle mesh; array properties are read-only views (no copy)."""
    def __init__(self, vertices: _Positions, faces: _Faces) -> None:
        """vertices (n, 3) float64/float32 (copied into the mesh), faces (m, 3) int, 0-based.
        Raises ValueError (shape, dtype), InputError (non-finite, id out of range, repeat)."""
    @property
    def num_vertices(self) -> int: ...
    @property
    def num_faces(self) -> int: ...
    @property
    def num_edges(self) -> int: ...
    @property
    def vertices(self) -> npt.NDArray[np.float64]:
        """(n, 3) float64 view."""
    @property
    def faces(self) -> npt.NDArray[np.int32]:
        """(m, 3) int32 view, file order."""
    @property
    def edges(self) -> npt.NDArray[np.int32]:
        """(e, 2) int32 view, first appearance over faces, each (min id, max id)."""
    @property
    def face_edges(self) -> npt.NDArray[np.int32]:
        """(m, 3) int32 view: edge of side k (corners k, (k+1)%3)."""
    def adjacency(self, kind: str) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int32]]:
        """CSR (offsets (rows+1,) int64, neighbours (total,) int32 view), rows sorted. kind:
        vertex_vertices, vertex_edges, vertex_faces, edge_faces, edge_edges, face_faces."""
    @property
    def report(self) -> dict[str, int]:
        """zero_area_faces, non_manifold_edges, boundary_edges, isolated_vertices,
        duplicate_faces."""

def read_mesh(path: _Path) -> TriMesh:
    """.obj .ply .off .x3d; raises ParseError (file, line or byte_offset)."""

def write_mesh(path: _Path, mesh: TriMesh) -> None:
    """By extension, atomically; positions round-trip bit for bit. ParseError if unwritable."""

def default_thickness(positions: _Positions, *, relative: float | None = None) -> float:
    """1e-3 (or relative, the CLI's --thickness-rel) of the bounding-box diagonal (the CLI's
    default thickness)."""

def methods() -> list[dict[str, Any]]:
    """Every method: name, summary, capabilities {exact, stochastic, uses_motion},
    params {key: (default, description)}."""

class VertexFaceContacts:
    """k vertex-face contacts sorted by (vertex, face); read-only views, row stride 64 bytes."""
    def __len__(self) -> int: ...
    @property
    def vertex(self) -> npt.NDArray[np.int32]:
        """(k,)"""
    @property
    def face(self) -> npt.NDArray[np.int32]:
        """(k,)"""
    @property
    def distance(self) -> npt.NDArray[np.float64]:
        """(k,) < thickness"""
    @property
    def barycentric(self) -> npt.NDArray[np.float64]:
        """(k, 3) of the closest point on the face"""
    @property
    def normal(self) -> npt.NDArray[np.float64]:
        """(k, 3) unit, from the face's closest point towards the vertex"""

class EdgeEdgeContacts:
    """k edge-edge contacts sorted by vertex ids of (a, b); read-only views, stride 72 bytes."""
    def __len__(self) -> int: ...
    @property
    def edges(self) -> npt.NDArray[np.int32]:
        """(k, 2) mesh edge ids of a and b"""
    @property
    def vertices(self) -> npt.NDArray[np.int32]:
        """(k, 2, 2): [:, 0] edge a's vertex ids (increasing), [:, 1] edge b's; a < b"""
    @property
    def s(self) -> npt.NDArray[np.float64]:
        """(k,) closest point on a = (1-s) x[a0] + s x[a1]"""
    @property
    def t(self) -> npt.NDArray[np.float64]:
        """(k,) closest point on b = (1-t) x[b0] + t x[b1]"""
    @property
    def distance(self) -> npt.NDArray[np.float64]:
        """(k,)"""
    @property
    def normal(self) -> npt.NDArray[np.float64]:
        """(k, 3) unit, from a's closest point towards b's"""

class TriangleTriangleContacts:
    """k intersecting face pairs sharing no vertex."""
    def __len__(self) -> int: ...
    @property
    def faces(self) -> npt.NDArray[np.int32]:
        """(k, 2), face0 < face1"""

class Contacts:
    """One update's contacts; its arrays stay valid while referenced (later updates never
    rewrite a live result)."""
    @property
    def vf(self) -> VertexFaceContacts: ...
    @property
    def ee(self) -> EdgeEdgeContacts: ...
    @property
    def tt(self) -> TriangleTriangleContacts: ...
    def __len__(self) -> int: ...
    def write(self, path: _Path) -> None:
        """The CLI's --contacts text format."""

class Detector:
    def __init__(self, method: str = "kdop", *, thickness: float, kinds: str = "vf,ee",
                 threads: int = 0) -> None:
        """method: the CLI's --method spec NAME[:key=value,...]; thickness h >= 0; kinds:
        comma-separated vf, ee, tt; threads: 0 = all. InputError on bad values."""
    def set_topology(self, mesh: TriMesh) -> None: ...
    @overload
    def update(self, positions: _Positions) -> Contacts: ...
    @overload
    def update(self, previous: _Positions, positions: _Positions) -> Contacts:
        """update(positions) or update(previous, positions); (n, 3) real arrays. float64
        C-contiguous: read in place; float32 or rows at a byte stride (buf[:, 0:3] of an
        interleaved vertex buffer): read in place, converted once inside the detector; other
        dtypes/layouts: copied once. GIL released while detecting. ValueError (shape, count),
        InputError (non-finite), RuntimeError (no topology, or in use by another thread)."""
    @property
    def stats(self) -> dict[str, float]: ...
    @property
    def last_positions_copied(self) -> bool:
        """Whether the last update's positions were converted rather than read in place."""
    @property
    def last_positions_conversion(self) -> str:
        """'none' (read in place), 'detector' (converted once inside the detector, no copy
        by the binding) or 'binding' (copied first)."""
    @property
    def last_update_ms(self) -> float:
        """Wall time of the last update's library call alone (the CLI's detect --json 'ms')."""
    @property
    def method(self) -> str: ...
    @property
    def thickness(self) -> float: ...
    @property
    def kinds(self) -> str: ...
    @property
    def threads(self) -> int: ...
    @property
    def capabilities(self) -> dict[str, bool]: ...
    def save_state(self) -> str: ...
    def load_state(self, text: str) -> None: ...

class VertexFaceImpacts:
    """k vertex-face impacts sorted by (vertex, face); read-only views over the records."""
    def __len__(self) -> int: ...
    @property
    def vertex(self) -> npt.NDArray[np.int32]:
        """(k,)"""
    @property
    def face(self) -> npt.NDArray[np.int32]:
        """(k,)"""
    @property
    def toi(self) -> npt.NDArray[np.float64]:
        """(k,) conservative time of impact in [0, 1]"""
    @property
    def distance(self) -> npt.NDArray[np.float64]:
        """(k,) at toi"""
    @property
    def barycentric(self) -> npt.NDArray[np.float64]:
        """(k, 3) of the closest point on the face at toi"""
    @property
    def normal(self) -> npt.NDArray[np.float64]:
        """(k, 3) unit, from the face's closest point towards the vertex, at toi"""
    @property
    def outcome(self) -> npt.NDArray[np.uint8]:
        """(k,) index into ccd_outcomes()"""

class EdgeEdgeImpacts:
    """k edge-edge impacts sorted by vertex ids of (a, b); read-only views over the records."""
    def __len__(self) -> int: ...
    @property
    def edges(self) -> npt.NDArray[np.int32]:
        """(k, 2) mesh edge ids of a and b"""
    @property
    def vertices(self) -> npt.NDArray[np.int32]:
        """(k, 2, 2): [:, 0] edge a's vertex ids (increasing), [:, 1] edge b's; a < b"""
    @property
    def toi(self) -> npt.NDArray[np.float64]:
        """(k,) conservative time of impact in [0, 1]"""
    @property
    def distance(self) -> npt.NDArray[np.float64]:
        """(k,) at toi"""
    @property
    def s(self) -> npt.NDArray[np.float64]:
        """(k,) closest point on a at toi = (1-s) a0 + s a1"""
    @property
    def t(self) -> npt.NDArray[np.float64]:
        """(k,) closest point on b at toi = (1-t) b0 + t b1"""
    @property
    def normal(self) -> npt.NDArray[np.float64]:
        """(k, 3) unit, from a's closest point towards b's, at toi"""
    @property
    def outcome(self) -> npt.NDArray[np.uint8]:
        """(k,) index into ccd_outcomes()"""

class Impacts:
    """One continuous query's impacts; its arrays stay valid while referenced (later queries
    never rewrite a live result)."""
    @property
    def vf(self) -> VertexFaceImpacts: ...
    @property
    def ee(self) -> EdgeEdgeImpacts: ...
    @property
    def collision_free_step(self) -> float:
        """The earliest toi, or 1 without impacts."""
    def __len__(self) -> int: ...
    def write(self, path: _Path) -> None:
        """The CLI's `ccd --impacts` text format."""

class ContinuousQuery:
    """Continuous collision detection over a mesh's topology, kept across steps; vertices move
    linearly from previous to current over t in [0, 1]."""
    def __init__(self, mesh: TriMesh, *, min_separation: float = 0.0, method: str = "kdop",
                 threads: int = 0, time_tolerance: float = 1e-6,
                 distance_tolerance: float = 1e-6, separation_tolerance: float = 0.01,
                 max_boxes: int = 10000) -> None:
        """min_separation delta >= 0; method kdop, hash or sap with parameters; threads 0 =
        all; the narrow phase's options. InputError on bad values."""
    def query(self, previous: _Positions, current: _Positions) -> Impacts:
        """(n, 3) real arrays; float64 C-contiguous read in place, others converted once.
        GIL released. ValueError (shape, count), InputError (non-finite), RuntimeError (in
        use by another thread)."""
    @property
    def stats(self) -> dict[str, float]: ...
    @property
    def last_positions_copied(self) -> bool: ...
    @property
    def min_separation(self) -> float: ...
    @property
    def method(self) -> str: ...
    @property
    def threads(self) -> int: ...

def continuous_impacts(mesh: TriMesh, previous: _Positions, current: _Positions, *,
                       min_separation: float = 0.0, method: str = "kdop", threads: int = 0,
                       time_tolerance: float = 1e-6, distance_tolerance: float = 1e-6,
                       separation_tolerance: float = 0.01, max_boxes: int = 10000) -> Impacts:
    """ContinuousQuery(mesh, ...).query(previous, current) in one call."""

def collision_free_step(mesh: TriMesh, previous: _Positions, current: _Positions, *,
                        min_separation: float = 0.0, method: str = "kdop", threads: int = 0,
                        time_tolerance: float = 1e-6, distance_tolerance: float = 1e-6,
                        separation_tolerance: float = 0.01, max_boxes: int = 10000) -> float:
    """The earliest conservative toi of the step (nothing comes within min_separation before
    it), or 1."""

def ccd_outcomes() -> list[str]:
    """Outcome names by code: 'hit-tolerance' certified; other 'hit-*' conservative only."""

def scenes() -> list[dict[str, Any]]:
    """Every scene: name, summary, params {key: (default, description)}; the last, 'file',
    lists the keys of Simulation.from_mesh."""

def render(mesh: TriMesh, positions: _Positions | None = None, contacts: Contacts | None = None,
           width: int = 640, height: int = 480, *, yaw: float = 30.0, pitch: float = 20.0,
           distance: float | None = None, wireframe: bool = False,
           supersample: int = 2) -> npt.NDArray[np.uint8]:
    """(height, width, 3) uint8 RGB picture of the mesh at positions ((n, 3) real, default its
    own), edges in contact in red, as the CLI's `render FILE`. GIL released while drawing."""

class Simulation:
    """Mass-spring cloth with obstacles and self-collision response (the CLI's `simulate`).
    Settings keywords (None = the scene's): method, thickness, kinds, response, fail_safe,
    untangle, untangle_pull ("after" | "solve"), motion_search, motion_retries, push_relaxation,
    response_from, passes, dt, substeps, integrator, threads. The scene's own step
    beyond an explicit integrator's stable range is split as the CLI splits it (time_step_fit);
    a given dt or substeps is kept, with a RuntimeWarning when beyond it."""
    def __init__(self, scene: str = "cloth-on-sphere", *, seed: int = 1, method: str | None = ...,
                 thickness: float | None = ..., kinds: str | None = ..., response: bool | None = ...,
                 fail_safe: bool | None = ..., untangle: bool | None = ...,
                 untangle_pull: str | None = ..., motion_search: bool | None = ...,
                 motion_retries: int | None = ..., push_relaxation: float | None = ...,
                 response_from: int | None = ...,
                 passes: int | None = ..., dt: float | None = ..., substeps: int | None = ...,
                 integrator: str | None = ..., threads: int = 0) -> None:
        """scene: NAME[:key=value,...] as the CLI's `simulate SPEC`; InputError on bad specs or
        values, TypeError on unknown keywords."""
    @staticmethod
    def from_mesh(mesh: TriMesh, params: str = "", *, method: str | None = ...,
                  thickness: float | None = ..., kinds: str | None = ...,
                  response: bool | None = ..., fail_safe: bool | None = ...,
                  untangle: bool | None = ..., untangle_pull: str | None = ...,
                  motion_search: bool | None = ..., motion_retries: int | None = ...,
                  push_relaxation: float | None = ..., response_from: int | None = ...,
                  passes: int | None = ..., dt: float | None = ...,
                  substeps: int | None = ..., integrator: str | None = ...,
                  threads: int = 0) -> Simulation:
        """A cloth from a mesh; params: the 'file' scene's keys, e.g. "pins=0;7,stiffness=500"."""
    def advance(self) -> dict[str, float]:
        """One frame; its figures (see current_stats). DivergenceError if a step diverges."""
    def run(self, frames: int) -> dict[str, npt.NDArray[Any]]:
        """frames frames; each current_stats key -> (frames,) int64/float64 array, plus
        bounds_min, bounds_max (frames, 3) float64. GIL released while stepping."""
    def current_stats(self) -> dict[str, float]:
        """frame, time, integrate_ms, detect_ms, response_ms, ccd_ms, ccd_impacts, ccd_queries,
        ccd_zone_vertices, ccd_frozen, vf, ee, tt, collision_share,
        min_distance, obstacle_penetration, cg_iterations, corrections, energy, max_speed,
        longest_spring, intersecting_pairs (-1 when not measured), contours, untangle_pulls, untangle_ms."""
    @property
    def positions(self) -> npt.NDArray[np.float64]:
        """(n, 3) copy."""
    @property
    def velocities(self) -> npt.NDArray[np.float64]:
        """(n, 3) copy."""
    @property
    def faces(self) -> npt.NDArray[np.int32]:
        """(m, 3) read-only view."""
    @property
    def pinned(self) -> npt.NDArray[np.bool_]:
        """(n,) driven particles."""
    def mesh(self) -> TriMesh:
        """A TriMesh of the current positions."""
    def contacts(self) -> Contacts:
        """Self-contacts at the current positions (the simulation's detector)."""
    def render(self, width: int = 640, height: int = 480, *, yaw: float = 30.0,
               pitch: float = 20.0, distance: float | None = None, wireframe: bool = False,
               springs: bool = False, contacts: bool = True,
               supersample: int = 2) -> npt.NDArray[np.uint8]:
        """(height, width, 3) uint8 RGB picture of the current frame (the CLI's `render`)."""
    @property
    def time(self) -> float: ...
    @property
    def frame(self) -> int: ...
    @property
    def num_vertices(self) -> int: ...
    @property
    def scene(self) -> str: ...
    @property
    def seed(self) -> int: ...
    @property
    def edge_length(self) -> float: ...
    @property
    def settings(self) -> dict[str, Any]: ...
    @property
    def time_step_fit(self) -> dict[str, Any]:
        """action ('stable', 'split', 'kept'), stable_dt, given_dt, given_substeps, dt, substeps."""
    @property
    def detector_stats(self) -> dict[str, float]: ...

__all__: Sequence[str]
