// The software rasteriser, the camera, the shared colouring rules and PNG output.
#include <crumple/core/error.hpp>
#include <crumple/mesh/mesh.hpp>
#include <crumple/render/camera.hpp>
#include <crumple/render/colouring.hpp>
#include <crumple/render/picture.hpp>
#include <crumple/render/rasteriser.hpp>

#include <gtest/gtest.h>

#include <support/stb_image.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>

#include <unistd.h>

namespace crumple::render {
namespace {

const Rgb kWhite{255, 255, 255};
const Rgb kRed{255, 0, 0};
const Rgb kGreen{0, 255, 0};
const Rgb kBlue{0, 0, 255};

/// Looks from +z at the origin, 90° field of view, distance 1: the plane z = 0 shows
/// [-1, 1]² over the whole (square) picture, x → column (0.5 + 0.5 X)·W, y → row (0.5 − 0.5 Y)·H.
Camera front_camera() {
  Camera c;
  c.yaw_deg = 0;
  c.pitch_deg = 0;
  c.distance = 1;
  c.fov_deg = 90;
  return c;
}

/// Flat lighting: every lit pixel has exactly its base colour.
void flat(Rasteriser& r) {
  r.lighting.ambient = 1;
  r.lighting.diffuse = 0;
}

int count(const Picture& p, Rgb c) {
  int n = 0;
  for (int y = 0; y < p.height(); ++y) {
    for (int x = 0; x < p.width(); ++x) n += p.at(x, y) == c;
  }
  return n;
}

TEST(Rasteriser, TriangleCoversTheExpectedPixels) {
  Rasteriser r(100, 100, front_camera(), kWhite);
  flat(r);
  // Screen corners (25, 75), (75, 75), (25, 25): the lower-left half of the central square.
  r.triangle({-0.5, -0.5, 0}, {0.5, -0.5, 0}, {-0.5, 0.5, 0}, kRed, kBlue);
  const Picture p = r.picture();
  EXPECT_EQ(p.at(30, 70), kRed);
  EXPECT_EQ(p.at(26, 26), kRed);
  EXPECT_EQ(p.at(74, 74), kRed);
  EXPECT_EQ(p.at(70, 30), kWhite) << "upper-right half";
  EXPECT_EQ(p.at(10, 50), kWhite);
  EXPECT_EQ(p.at(50, 90), kWhite);
  for (int y = 0; y < 100; ++y) {
    for (int x = 0; x < 100; ++x) {
      const bool inside = x >= 25 && y <= 74 && (x - 25) + (74 - y) <= 49;
      const bool strictly = x >= 26 && y <= 73 && (x - 25) + (74 - y) <= 48;
      if (strictly) {
        EXPECT_EQ(p.at(x, y), kRed) << x << "," << y;
      }
      if (!inside) {
        EXPECT_EQ(p.at(x, y), kWhite) << x << "," << y;
      }
    }
  }
  EXPECT_NEAR(count(p, kRed), 50 * 50 / 2, 60);
}

TEST(Rasteriser, DepthTestKeepsTheNearestWhateverTheOrder) {
  for (const bool near_first : {true, false}) {
    Rasteriser r(64, 64, front_camera(), kWhite);
    flat(r);
    const auto square = [&](double z, Rgb c) {
      r.triangle({-0.5, -0.5, z}, {0.5, -0.5, z}, {0.5, 0.5, z}, c, c);
      r.triangle({-0.5, -0.5, z}, {0.5, 0.5, z}, {-0.5, 0.5, z}, c, c);
    };
    const auto far_square = [&] { square(0, kRed); };
    const auto near_square = [&] { square(0.2, kGreen); };  // z = 0.2 is closer to the eye at +z
    if (near_first) {
      near_square();
      far_square();
    } else {
      far_square();
      near_square();
    }
    const Picture p = r.picture();
    EXPECT_EQ(p.at(32, 32), kGreen) << "near_first=" << near_first;
    EXPECT_EQ(count(p, kRed), 0) << "the nearer square is larger on screen and hides the other";
  }
}

TEST(Rasteriser, LinesAreHiddenBehindTheSurfaceButDrawnOnIt) {
  Rasteriser r(64, 64, front_camera(), kWhite);
  flat(r);
  r.triangle({-1, -1, 0.1}, {1, -1, 0.1}, {0, 1, 0.1}, kBlue, kBlue);
  r.line({-0.5, 0, 0}, {0.5, 0, 0}, kRed, 1);              // behind the triangle
  r.line({-0.5, -0.5, 0.1}, {0.5, -0.5, 0.1}, kGreen, 1);  // lying on it
  const Picture p = r.picture();
  EXPECT_EQ(p.at(32, 32), kBlue);
  EXPECT_EQ(count(p, kRed), 0);
  EXPECT_GT(count(p, kGreen), 20);
}

TEST(Rasteriser, TwoSidedLightingColoursAndLightsBothSides) {
  const auto render = [](bool flip) {
    Rasteriser r(32, 32, front_camera(), kWhite);
    r.lighting.ambient = 0.3;
    r.lighting.diffuse = 0.7;
    r.lighting.direction = Vec3(0, 0, 1);  // headlight along the view axis
    const Vec3 a(-1, -1, 0), b(1, -1, 0), c(0, 1, 0);
    if (flip) {
      r.triangle(a, c, b, Rgb{200, 200, 200}, Rgb{100, 100, 100});
    } else {
      r.triangle(a, b, c, Rgb{200, 200, 200}, Rgb{100, 100, 100});
    }
    return r.picture().at(16, 16);
  };
  EXPECT_EQ(render(false), (Rgb{200, 200, 200})) << "front side, normal towards the light";
  EXPECT_EQ(render(true), (Rgb{100, 100, 100})) << "back side: its own colour, lit as well";

  // Tilted away from the light: Lambert dims it, the same on both sides.
  Camera cam = front_camera();
  Rasteriser r(32, 32, cam, kWhite);
  r.lighting.ambient = 0.3;
  r.lighting.diffuse = 0.7;
  r.lighting.direction = Vec3(0, 0, 1);
  const double s = std::sin(M_PI / 3), c = std::cos(M_PI / 3);  // normal at 60° from the view axis
  r.triangle({-c, -1, s}, {c, -1, -s}, {0, 1, 0}, Rgb{200, 200, 200}, Rgb{200, 200, 200});
  const Rgb lit = r.picture().at(16, 16);
  EXPECT_NEAR(lit.r, 200 * (0.3 + 0.7 * 0.5), 2.0);
}

TEST(Rasteriser, SupersamplingAveragesEdges) {
  Rasteriser r(20, 20, front_camera(), Rgb{0, 0, 0}, 4);
  flat(r);
  r.triangle({-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, kWhite, kWhite);  // diagonal through pixel centres
  const Picture p = r.picture();
  // Covered: below the diagonal x + y = 20 (screen pixels).
  EXPECT_EQ(p.at(15, 15), kWhite);
  EXPECT_EQ(p.at(5, 5), (Rgb{0, 0, 0})) << "above the diagonal: black";
  const Rgb d = p.at(9, 10);
  EXPECT_GT(d.r, 60);
  EXPECT_LT(d.r, 200) << "a pixel on the diagonal is grey";
  EXPECT_THROW(Rasteriser(10, 10, front_camera(), kWhite, 5), InputError);
  EXPECT_THROW(Rasteriser(0, 10, front_camera(), kWhite), InputError);
}

TEST(Camera, ProjectUnprojectAndFit) {
  Camera cam;
  cam.yaw_deg = 35;
  cam.pitch_deg = -20;
  const Bounds b{Vec3(-1, 2, 0), Vec3(3, 4, 0.5)};
  cam.fit(b, 800.0 / 600);
  for (int i = 0; i < 8; ++i) {
    const Vec3 corner((i & 1) ? b.max.x() : b.min.x(), (i & 2) ? b.max.y() : b.min.y(),
                      (i & 4) ? b.max.z() : b.min.z());
    const auto s = cam.project(corner, 800, 600);
    ASSERT_TRUE(s);
    EXPECT_GE(s->x, 0);
    EXPECT_LE(s->x, 800);
    EXPECT_GE(s->y, 0);
    EXPECT_LE(s->y, 600);
    EXPECT_LT((cam.unproject(s->x, s->y, s->depth, 800, 600) - corner).norm(), 1e-9);
  }
  const auto centre = cam.project(0.5 * (b.min + b.max), 800, 600);
  EXPECT_NEAR(centre->x, 400, 1e-9);
  EXPECT_NEAR(centre->y, 300, 1e-9);
  EXPECT_FALSE(cam.project(cam.eye() - cam.forward(), 800, 600)) << "behind the eye";
  // The GL matrices agree with project().
  const Vec3 p(0.3, 2.5, 0.1);
  const Eigen::Vector4d clip = cam.projection_matrix(800.0 / 600) * cam.view_matrix() *
                               Eigen::Vector4d(p.x(), p.y(), p.z(), 1);
  const auto s = cam.project(p, 800, 600);
  EXPECT_NEAR((0.5 + 0.5 * clip.x() / clip.w()) * 800, s->x, 1e-6);
  EXPECT_NEAR((0.5 - 0.5 * clip.y() / clip.w()) * 600, s->y, 1e-6);
  EXPECT_NEAR(clip.w(), s->depth, 1e-9);
}

TEST(Camera, PickVertexTakesTheNearestProjection) {
  const Camera cam = front_camera();
  const Positions x{Vec3(0, 0, 0), Vec3(0.5, 0, 0), Vec3(0, 0, 0.5)};  // 0 and 2 project alike
  EXPECT_EQ(pick_vertex(cam, x, 50, 50, 100, 100), 2) << "the one nearer the eye";
  EXPECT_EQ(pick_vertex(cam, x, 76, 51, 100, 100), 1);
  EXPECT_EQ(pick_vertex(cam, x, 5, 5, 100, 100), -1);
}

/// A strip of quads along x in the plane z = 0: (n+1) × 2 vertices.
TriMesh strip(int n) {
  Positions x;
  std::vector<Face> faces;
  for (int i = 0; i <= n; ++i) {
    x.emplace_back(-0.8 + 1.6 * i / n, -0.3, 0);
    x.emplace_back(-0.8 + 1.6 * i / n, 0.3, 0);
  }
  for (int i = 0; i < n; ++i) {
    const Index a = 2 * i, b = 2 * i + 1, c = 2 * i + 2, d = 2 * i + 3;
    faces.push_back({a, c, d});
    faces.push_back({a, d, b});
  }
  return TriMesh::create(std::move(x), std::move(faces));
}

Index edge_id(const Topology& t, Index u, Index v) {
  for (Index e = 0; e < t.num_edges(); ++e) {
    if (t.edge(e) == Edge{std::min(u, v), std::max(u, v)}) return e;
  }
  return -1;
}

TEST(Colouring, CollidingEdgesFollowTheCollisionShareRule) {
  const TriMesh mesh = strip(4);
  const Topology& t = mesh.topology();
  ContactSet contacts;
  const Index e0 = edge_id(t, 0, 1), e1 = edge_id(t, 6, 7);
  contacts.ee.push_back(
      make_edge_edge_contact(e0, t.edge(e0), e1, t.edge(e1), 0.01, 0.5, 0.5, Vec3::UnitX()));
  contacts.vf.push_back({9, 2, 0.01, Vec3(1, 0, 0), Vec3::UnitZ()});
  const std::vector<bool> hit = colliding_edges(t, contacts);
  std::vector<Index> expected{e0, e1};
  for (Index e : t.face_edges(2)) expected.push_back(e);
  for (Index e = 0; e < t.num_edges(); ++e) {
    const bool want = std::find(expected.begin(), expected.end(), e) != expected.end();
    EXPECT_EQ(hit[static_cast<std::size_t>(e)], want) << "edge " << e;
  }
  const auto segments = contact_segments(t, mesh.positions(), contacts);
  ASSERT_EQ(segments.size(), 1u);
  EXPECT_EQ(segments[0].a, mesh.positions()[9]);
  EXPECT_EQ(segments[0].b, mesh.positions()[static_cast<std::size_t>(t.face(2)[0])]);
}

TEST(Colouring, RedPixelsExactlyWhereCollidingEdgesProject) {
  const TriMesh mesh = strip(4);
  const Topology& t = mesh.topology();
  ContactSet contacts;
  const Index e0 = edge_id(t, 0, 1), e1 = edge_id(t, 6, 7);
  contacts.ee.push_back(
      make_edge_edge_contact(e0, t.edge(e0), e1, t.edge(e1), 0.01, 0.5, 0.5, Vec3::UnitX()));
  const Camera cam = front_camera();
  DrawOptions options;
  options.wireframe = true;
  const Frame frame{&t, mesh.positions(), &contacts, {}, {}, {}};
  const Picture p = render_frame(frame, cam, 200, 200, options, 1);
  // Vertical edges at x = -0.8 (column 20) and x = 0.4 (column 140), rows 70..130.
  int red = 0;
  for (int y = 0; y < 200; ++y) {
    for (int x = 0; x < 200; ++x) {
      if (!is_collision_red(p.at(x, y))) continue;
      ++red;
      const bool near_edge =
          (std::abs(x - 20) <= 2 || std::abs(x - 140) <= 2) && y >= 68 && y <= 132;
      EXPECT_TRUE(near_edge) << "red at " << x << "," << y;
    }
  }
  EXPECT_GT(red, 2 * 50);
  EXPECT_TRUE(is_collision_red(p.at(20, 100)));
  EXPECT_TRUE(is_collision_red(p.at(140, 100)));
  EXPECT_FALSE(is_collision_red(p.at(60, 100))) << "a wireframe edge not in collision";
  EXPECT_FALSE(is_collision_red(p.at(100, 100)));

  // No contacts: no red at all.
  const ContactSet none;
  const Picture q =
      render_frame(Frame{&t, mesh.positions(), &none, {}, {}, {}}, cam, 200, 200, options, 1);
  for (int y = 0; y < 200; ++y) {
    for (int x = 0; x < 200; ++x) ASSERT_FALSE(is_collision_red(q.at(x, y))) << x << "," << y;
  }
}

TEST(Colouring, MassesAndSpringsMode) {
  const TriMesh mesh = strip(2);
  DrawOptions options;
  options.masses_springs = true;
  const std::vector<Edge> springs{{0, 5}};
  const bool pinned[6] = {true, false, false, false, false, false};
  const Picture p =
      render_frame(Frame{&mesh.topology(), mesh.positions(), nullptr, springs, pinned, {}},
                   front_camera(), 100, 100, options, 1);
  EXPECT_EQ(p.at(10, 65), options.palette.pinned) << "vertex 0 at (-0.8, -0.3)";
  EXPECT_EQ(p.at(90, 35), options.palette.mass) << "vertex 5 at (0.8, 0.3)";
  EXPECT_EQ(p.at(50, 50), options.palette.spring) << "the one spring crosses the centre";
  EXPECT_EQ(p.at(30, 65), options.palette.background) << "no surface, no mesh edges";
}

TEST(Colouring, ObstacleMeshesLieOnTheirShapes) {
  const response::Sphere sphere{Vec3(1, 2, 3), 0.5};
  const ShapeMesh s = shape_mesh(sphere, Vec3::Zero(), 1);
  EXPECT_EQ(s.faces.size(), 2u * 32 * 16);
  for (const Vec3& p : s.positions) EXPECT_NEAR((p - sphere.center).norm(), 0.5, 1e-12);
  response::Box box;
  box.center = Vec3(0, 1, 0);
  box.half_extents = Vec3(1, 2, 3);
  const ShapeMesh b = shape_mesh(box, Vec3::Zero(), 1);
  EXPECT_EQ(b.faces.size(), 12u);
  for (const Vec3& p : b.positions) {
    const Vec3 q = (p - box.center).cwiseAbs().cwiseQuotient(box.half_extents);
    EXPECT_NEAR(q.maxCoeff(), 1, 1e-12) << "on the surface";
    EXPECT_NEAR(q.minCoeff(), 1, 1e-12) << "the 8 corners only";
  }
  const response::Plane floor{Vec3(0, -1, 0), Vec3::UnitY()};
  const ShapeMesh f = shape_mesh(floor, Vec3(5, 7, -2), 4);
  Vec3 mean = Vec3::Zero();
  for (const Vec3& p : f.positions) {
    EXPECT_NEAR(p.y(), -1, 1e-12);
    EXPECT_LE(std::max(std::abs(p.x() - 5), std::abs(p.z() + 2)), 2 + 1e-12) << "4 wide around the centre";
    mean += p / static_cast<double>(f.positions.size());
  }
  EXPECT_NEAR((mean - Vec3(5, -1, -2)).norm(), 0, 1e-12);
  // Obstacles are drawn where they are at the frame's time.
  response::Obstacle moving{sphere};
  moving.velocity = Vec3(2, 0, 0);
  const Positions cloth{Vec3(0, 0, 0), Vec3(1, 0, 0)};
  const std::vector<ShapeMesh> at_1 = obstacle_meshes({&moving, 1}, 1.0, cloth);
  ASSERT_EQ(at_1.size(), 1u);
  for (const Vec3& p : at_1[0].positions) EXPECT_NEAR((p - Vec3(3, 2, 3)).norm(), 0.5, 1e-12);
}

TEST(Colouring, ObstaclesAreDrawnBehindTheCloth) {
  // A strip in z = 0 in front of a sphere centred behind it: the sphere shows around the strip,
  // the strip hides it where they overlap.
  const TriMesh mesh = strip(2);
  const response::Obstacle sphere{response::Sphere{Vec3(0, 0, -1.2), 1}};
  const std::vector<ShapeMesh> shapes = obstacle_meshes({&sphere, 1}, 0, mesh.positions());
  DrawOptions options;
  options.colliding_edges = false;
  const Picture p = render_frame(Frame{&mesh.topology(), mesh.positions(), nullptr, {}, {}, shapes},
                                 front_camera(), 100, 100, options, 1);
  const auto grey = [](Rgb c) { return c.r == c.g && std::abs(c.r - c.b) < 12 && c.r < 250; };
  EXPECT_TRUE(grey(p.at(50, 30))) << "the sphere above the strip";
  EXPECT_FALSE(grey(p.at(50, 50))) << "the strip in front of it";
  EXPECT_EQ(p.at(3, 3), options.palette.background);
}

TEST(Picture, PngRoundTripsAndIsWrittenAtomically) {
  Picture p(7, 5, kWhite);
  p.set(3, 2, kRed);
  p.set(6, 4, Rgb{1, 2, 3});
  const auto dir =
      std::filesystem::temp_directory_path() / ("crumple-render-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const auto path = dir / "p.png";
  write_png(path, p);
  int w = 0, h = 0, n = 0;
  unsigned char* data = stbi_load(path.c_str(), &w, &h, &n, 3);
  ASSERT_NE(data, nullptr);
  EXPECT_EQ(w, 7);
  EXPECT_EQ(h, 5);
  EXPECT_TRUE(std::equal(p.data().begin(), p.data().end(), data));
  stbi_image_free(data);
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    EXPECT_EQ(entry.path().filename(), "p.png");
  EXPECT_THROW(write_png(dir / "missing" / "p.png", p), ParseError);
  std::filesystem::remove_all(dir);

  Picture q(2, 3, kWhite);
  q.set(0, 0, kRed);
  q.flip_vertically();
  EXPECT_EQ(q.at(0, 2), kRed);
  EXPECT_EQ(q.at(0, 0), kWhite);
  EXPECT_THROW(Picture(0, 1), InputError);
}

}  // namespace
}  // namespace crumple::render
