#pragma once
/// \file
/// Untangling a mesh that already passes through itself: Global Intersection Analysis (Baraff,
/// Witkin, Kass, *Untangling Cloth*, SIGGRAPH 2003; ALGORITHMS-2 §4) and the pushes that pull
/// the regions it finds back through, with Intersection Contour Minimization (Volino &
/// Magnenat-Thalmann 2006) for contours that bound no region. docs/simulation.md, "Untangling".
///
/// Analysis (`analyse_intersections`), from the intersecting triangle pairs (faces sharing no
/// vertex, e.g. an exact detector's `tt` contacts):
///  1. **Crossings**: every edge of one face of a pair that meets the other face (exact
///     `segment_triangle_intersect`); a crossing is an (edge, face) pair, shared by the pairs
///     of the edge's faces with that face.
///  2. **Contours**: the crossings chained through the pairs (union–find: the crossings of one
///     pair belong to one contour). A contour is *open* when a crossing edge is a boundary edge
///     (the intersection curve reaches the cloth's border).
///  2b. **Pinches**: a curve of one sheet that ends inside the cloth ends at a vertex whose star
///     passes through itself (two of its faces sharing only that vertex intersect; `tt` pairs
///     leave such faces out), where the curve's two preimages meet. Every vertex of the mesh is
///     tried (`find_pinch_crossings`); the crossings of those faces join the pinch to its
///     contour, or make a contour of their own (a pinch alone: no `tt` pair), and the faces'
///     corners join the tangle.
///  3. **Regions**: the mesh's vertices flood-filled along edges, the contour's crossing edges
///     cut and its pinches removed (they are on the curve, which closes through them). In each
///     connected piece of the mesh the largest part is *outside*; every other part is *inside*:
///     the smaller side of the curve, which went through. A part holding a pinned vertex
///     (m⁻¹ = 0) cannot go back through, so when one exists the largest pinned part is the
///     outside instead. This also handles open contours: a flap of the cloth whose intersection
///     curve runs from its border to its border is cut off and is the inside; a curve that cuts
///     nothing (from the border of one sheet to the border of another, a slit) has no inside.
///     A curve from the border to a pinch cuts nothing either (its second preimage ends inside
///     the face its border side passes through); it is closed from that face to the border
///     across the fewest edges (`Contour::closure`, also cut), which cuts off the flap on that
///     side of the curve: flipping it through moves the pinch along the fold to the cloth's end.
///     When that flap is not the smaller side (it holds a pin) the closure is dropped and the
///     curve has no inside.
///  3b. **Bands**: a long curve that cuts off only a thin band of pockets (`Contour::band`: at
///     least 32 crossings, at most one inside vertex per 4) is a long fold through a sheet, its
///     crease just beyond the sheet. Pulling both sides there moves the sheet into the fold's
///     next stretch, which the next frame finds through again (the pulls see-saw along the
///     fold): a band's pulls move the inside end alone, the crossed face held.
///  3c. **Short folds**: a closed curve between two or more pinches enclosing 1 to 4 vertices
///     (`Contour::short_fold`) is a short stretch of a fold folded beyond flat. Pulled alone,
///     such curves walked along the fold without closing (docs/simulation.md); its crossings
///     also get contour minimisation, which shortens the curve towards its pinches until it
///     closes.
///
/// Pushes (`Untangler::apply`), built at the analysed positions, applied after each step (or,
/// for the pulls, held inside an implicit step as anchors: `Untangler::pull_moves`):
///  - a crossing whose edge has one end inside (or at a pinch of its contour: the part of the
///    edge between the pinch and the crossing is inside) and one outside: the inside end and
///    the crossed face (at the crossing's barycentric point) get a position impulse in the
///    stencil form of `contact_response.hpp` along the face's normal turned towards the outside end — the
///    repulsion with its sign flipped for the pair, so the inside end passes back through the
///    face to a gap of the thickness h — at most `max_step` per call, and their approaching
///    relative velocity along it is removed; a band's pull (3b) moves the inside end alone (the
///    face held, the end's own velocity against the pull removed);
///  - a crossing of a pinch alone (a contour with no `tt` pair): the end of the edge nearer the
///    face's plane is pulled back through it, as above;
///  - any other crossing of a contour with no inside, and every crossing of a short fold (3c),
///    besides its pulls: its edge's ends move by +σG, the face's
///    corners by −σG (σ = `contour_step`), G the direction that shortens the intersection curve:
///    Σ over the edge's faces f of R_f − (E·R_f)/(E·N) N (E the edge's direction, N the
///    face's normal, R_f the curve's direction into f), normalised — the first-order change of
///    the curve's length when the edge moves (the N term dropped when |E·N| is tiny). The
///    border crossings of a contour that ends at a pinch move by σ_b (`border_step`) instead:
///    a curve from the border to a pinch left with no inside (its flap holds a pin) encloses
///    nothing, and its border end is the only end that can leave the cloth.
/// The vertices of inside regions and of intersecting faces, and for a curve ending at a pinch
/// (a fold folded beyond flat there) every vertex one edge from its crossing edges and crossed
/// faces, form the *tangle*; a contact or
/// impact whose two sides both touch the tangle is exempt from the regular response and the
/// fail-safe (`touches_tangle_on_both_sides`), which would otherwise hold the intersection in
/// place.

#include <crumple/core/types.hpp>
#include <crumple/detect/contact.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/response/contact_response.hpp>

#include <cstddef>
#include <memory>
#include <span>
#include <vector>

namespace crumple::response {

/// A mesh edge passing through a face it shares no vertex with.
struct Crossing {
  Index edge = -1;
  Index face = -1;
  /// Of the crossing point w.r.t. the face's corners (clamped into the face; the closest point
  /// of the face for an edge lying in its plane).
  Vec3 barycentric = Vec3::Zero();
  Index contour = -1;
};

/// One intersection curve.
struct Contour {
  std::vector<Index> crossings;  ///< indices into `IntersectionAnalysis::crossings`
  std::size_t pairs = 0;         ///< intersecting face pairs along it
  bool open = false;             ///< a crossing edge is a boundary edge
  /// Pinch vertices where the curve ends inside the cloth (sorted): two faces of the vertex's
  /// star, sharing only it, intersect. The flood fill goes around them (they are on the curve).
  std::vector<Index> pinches;
  /// Parts of the mesh with the crossing edges cut (the connected pieces of the mesh when the
  /// curve cuts nothing off).
  std::size_t parts = 0;
  std::vector<Index> inside;     ///< vertices of its inside parts (sorted; empty: no inside)
  /// A curve from the border to a pinch: the edges that close it to the border, cutting off
  /// `inside` (see the file comment, 3); empty for any other curve, or when the flap it cut
  /// off held a pin.
  std::vector<Index> closure;
  /// Long, and what it cuts off is thin: at least 32 crossings and at most one inside vertex per
  /// 4 of them — a band of pockets along a long fold through a sheet (see the file comment, 3b).
  /// Its pulls move the inside end alone, the crossed face held.
  bool band = false;
  /// Closed, between two or more pinches (with `tt` pairs), and enclosing 1 to 4 vertices: a
  /// short stretch of a fold folded beyond flat (see the file comment, 3c). Its crossings get
  /// contour minimisation as well as the pulls.
  bool short_fold = false;
};

/// A side of a face of a vertex's star passing through another face of that star sharing only
/// the vertex: the star passes through itself (a *pinch*; `tt` pairs leave such faces out).
struct PinchCrossing {
  Index vertex = -1;     ///< the pinch
  Index edge = -1;       ///< the side of `edge_face` opposite `vertex`
  Index edge_face = -1;
  Index face = -1;       ///< the face it passes through
};

/// Every pinch crossing of the mesh at `x` (exact), by vertex, a face pair's crossings adjacent.
/// O(Σ star size²).
std::vector<PinchCrossing> find_pinch_crossings(const Topology& topology, PositionsView x);
/// Intersecting face pairs sharing exactly one vertex (the pinch pairs), each counted once.
std::size_t count_pinch_pairs(const Topology& topology, PositionsView x);

/// What `analyse_intersections` found.
struct IntersectionAnalysis {
  std::size_t pairs = 0;            ///< intersecting face pairs analysed
  std::size_t pinch_pairs = 0;      ///< intersecting face pairs sharing one vertex (all of the mesh)
  std::vector<Crossing> crossings;  ///< sorted by (edge, face)
  std::vector<Contour> contours;
  /// Per vertex: 1 for the tangle (inside some contour, or a corner of an intersecting face).
  std::vector<char> tangle;
  std::size_t inside_vertices = 0;  ///< vertices inside some contour
};

/// Global Intersection Analysis (see the file comment). `pairs`: intersecting faces sharing no
/// vertex (not checked: a pair that does not intersect gives no crossing); `inv_mass`: #V
/// entries (0 = pinned), or empty for no pins. Deterministic; O(#pairs + #contours × (#V + #E)).
IntersectionAnalysis analyse_intersections(const Topology& topology, PositionsView positions,
                                           std::span<const TriangleTriangleContact> pairs,
                                           std::span<const Scalar> inv_mass = {});

/// True when both sides of the stencil (VF: the vertex and the face; EE: the two edges) have a
/// vertex in `tangle` (#V flags; empty = none).
bool touches_tangle_on_both_sides(const Stencil& stencil, std::span<const char> tangle);

struct UntangleOptions {
  Scalar thickness = 0;     ///< h: a pulled-through end goes to the gap h beyond the face (>= 0)
  Scalar max_step = 0;      ///< largest position impulse of one push per `apply` (m, > 0)
  Scalar contour_step = 0;  ///< σ: contour-minimisation displacement per `apply` (m, >= 0)
  /// σ_b: the same for a border crossing of a contour that ends at a pinch and has no inside
  /// (the curve's only end that can leave the cloth; m, >= 0).
  Scalar border_step = 0;
  int threads = 1;          ///< threads of the intersection detector (0 = all)
};

/// One vertex's share of a pull (`Untangler::pull_moves`): `offset` (m) along `direction` (unit).
struct PullMove {
  Index vertex = -1;
  Vec3 direction = Vec3::Zero();
  Scalar offset = 0;
};

/// What one `apply` did.
struct UntangleStats {
  std::size_t pulls = 0;       ///< pull-through pushes that moved something
  std::size_t contour_moves = 0;  ///< contour-minimisation moves
};

/// Finds intersections (the exact `kdop` detector, kinds `tt`), analyses them, and pushes.
class Untangler {
 public:
  /// Throws `InputError` for bad options.
  Untangler(std::shared_ptr<const Topology> topology, UntangleOptions options);

  /// Detects the intersecting pairs at `positions`, analyses them and builds the pushes (from
  /// these positions). Returns the number of intersecting pairs.
  std::size_t analyse(PositionsView positions, std::span<const Scalar> inv_mass);
  /// Only counts the intersecting pairs (and the pinch pairs) at `positions` (no analysis; the
  /// pushes are cleared).
  std::size_t count(PositionsView positions);

  /// Applies the pushes of the last analysis at the current positions (see the file comment).
  /// `pulls_moved`: the pulls' moves were held inside the step just taken (`pull_moves`), so
  /// only their velocity corrections (and the contour moves) are applied.
  UntangleStats apply(std::span<const Scalar> inv_mass, std::span<Vec3> positions,
                      std::span<Vec3> velocities, bool pulls_moved = false) const;
  /// The moves the pulls of the last analysis would give their vertices at `positions` (each
  /// stencil vertex's share of the position impulse `apply` makes, along the pull's normal), for
  /// an implicit step that holds them as anchors (`sim::Anchor`) instead of `apply` moving the
  /// vertices after it. Appends to `out`; returns the number of pulls with a move.
  std::size_t pull_moves(std::span<const Scalar> inv_mass, PositionsView positions,
                         std::vector<PullMove>& out) const;

  const IntersectionAnalysis& analysis() const { return analysis_; }
  /// The tangle of the last analysis (#V flags, all 0 when the mesh was clean).
  std::span<const char> tangle() const { return analysis_.tangle; }
  /// Intersecting face pairs sharing one vertex at the last analysis or count.
  std::size_t pinch_pairs() const { return analysis_.pinch_pairs; }
  /// Some face pair intersected at the last analysis (a `tt` pair or a pinch pair).
  bool tangled() const { return analysis_.pairs > 0 || analysis_.pinch_pairs > 0; }
  const UntangleOptions& options() const { return options_; }

 private:
  struct Shift {
    std::array<Index, 5> vertex{-1, -1, -1, -1, -1};  ///< the edge's two ends, the face's corners
    Vec3 direction = Vec3::Zero();                     ///< G (unit)
    Scalar step = 0;                                   ///< σ or σ_b
  };

  std::shared_ptr<const Topology> topology_;
  UntangleOptions options_;
  std::unique_ptr<Detector> detector_;
  ContactSet contacts_;
  IntersectionAnalysis analysis_;
  std::vector<Stencil> pulls_;
  std::vector<char> held_face_;  ///< per pull: 1 for a band's (the crossed face is held)
  std::vector<Shift> shifts_;

  /// Pull `p` as it acts: a band's stencil cut to its inside end.
  Stencil acting_pull(std::size_t p) const;
  /// The position impulse μ of pull `p`, acting as `s` (`acting_pull`), at `x` (0: nothing to move).
  Scalar pull_impulse(std::size_t p, const Stencil& s, std::span<const Scalar> inv_mass, PositionsView x) const;
};

}  // namespace crumple::response
