#include <crumple/core/atomic_file.hpp>
#include <crumple/core/error.hpp>
#include <crumple/detect/contact.hpp>

#include <algorithm>
#include <charconv>
#include <cstddef>
#include <vector>
#include <tuple>

namespace crumple {

ContactKinds ContactKinds::parse(std::string_view list) {
  ContactKinds kinds{false, false, false};
  std::size_t start = 0;
  while (start <= list.size()) {
    const std::size_t end = std::min(list.find(',', start), list.size());
    const std::string_view item = list.substr(start, end - start);
    if (item == "vf") {
      kinds.vf = true;
    } else if (item == "ee") {
      kinds.ee = true;
    } else if (item == "tt") {
      kinds.tt = true;
    } else {
      throw InputError("unknown contact kind '" + std::string(item) +
                       "' (expected a comma-separated list of vf, ee, tt)");
    }
    start = end + 1;
  }
  return kinds;
}

std::string ContactKinds::to_string() const {
  std::string out;
  const auto add = [&](bool on, const char* name) {
    if (!on) return;
    if (!out.empty()) out += ",";
    out += name;
  };
  add(vf, "vf");
  add(ee, "ee");
  add(tt, "tt");
  return out;
}

namespace {

/// Sorts `v` by `less`, whose first criterion is the non-negative id `first(x)`: a counting
/// sort on that id (one pass to count, one to scatter), then each bucket — a vertex's few
/// contacts — sorted by `less`. The exact detectors return 100k-600k contacts per frame on the
/// real meshes, where std::sort moving 72-byte records took 60 ms.
template <class T, class First, class Less>
void sort_by_first(std::vector<T>& v, First first, Less less) {
  if (std::is_sorted(v.begin(), v.end(), less)) return;
  Index top = 0;
  for (const T& x : v) top = std::max(top, first(x));
  if (v.size() < 4096 || static_cast<std::size_t>(top) > 4 * v.size() + 4096) {
    std::sort(v.begin(), v.end(), less);
    return;
  }
  std::vector<std::size_t> end(static_cast<std::size_t>(top) + 1, 0);  // then: end of each bucket
  for (const T& x : v) ++end[static_cast<std::size_t>(first(x))];
  std::size_t sum = 0;
  for (std::size_t& e : end) {
    sum += e;
    e = sum - e;  // start of the bucket, advanced to its end by the scatter
  }
  // Scatter into the upper half of the list itself, then copy back: the caller's ContactSet
  // keeps that capacity from frame to frame, where a fresh 30 MB buffer per frame would cost
  // as much in page faults as the sort.
  const std::size_t n = v.size();
  v.resize(2 * n);
  for (std::size_t i = 0; i < n; ++i) v[n + end[static_cast<std::size_t>(first(v[i]))]++] = v[i];
  std::copy(v.begin() + static_cast<std::ptrdiff_t>(n), v.end(), v.begin());
  v.resize(n);
  std::size_t begin = 0;
  for (const std::size_t e : end) {
    if (e - begin > 1) {
      std::sort(v.begin() + static_cast<std::ptrdiff_t>(begin), v.begin() + static_cast<std::ptrdiff_t>(e), less);
    }
    begin = e;
  }
}

}  // namespace

void ContactSet::sort() {
  sort_by_first(
      vf, [](const VertexFaceContact& c) { return c.vertex; },
      [](const auto& x, const auto& y) { return std::tie(x.vertex, x.face) < std::tie(y.vertex, y.face); });
  sort_by_first(
      ee, [](const EdgeEdgeContact& c) { return c.a[0]; },
      [](const auto& x, const auto& y) { return std::tie(x.a, x.b) < std::tie(y.a, y.b); });
  sort_by_first(
      tt, [](const TriangleTriangleContact& c) { return c.face0; },
      [](const auto& x, const auto& y) { return std::tie(x.face0, x.face1) < std::tie(y.face0, y.face1); });
}

namespace {
void put_double(std::ostream& out, double value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, value, std::chars_format::general, 17);
  out.write(buffer, result.ptr - buffer);
}
}  // namespace

void write_contacts(std::ostream& out, const ContactSet& set) {
  for (const auto& c : set.vf) {
    out << "vf " << c.vertex << ' ' << c.face << ' ';
    put_double(out, c.distance);
    out << '\n';
  }
  for (const auto& c : set.ee) {
    out << "ee " << c.a[0] << ' ' << c.a[1] << ' ' << c.b[0] << ' ' << c.b[1] << ' ';
    put_double(out, c.distance);
    out << '\n';
  }
  for (const auto& c : set.tt) out << "tt " << c.face0 << ' ' << c.face1 << '\n';
}

void write_contacts_file(const std::filesystem::path& path, const ContactSet& set) {
  write_file_atomically(path, [&](std::ostream& out) { write_contacts(out, set); });
}

EdgeEdgeContact make_edge_edge_contact(Index edge0, const Edge& a, Index edge1, const Edge& b,
                                       Scalar distance, Scalar s, Scalar t, const Vec3& normal) {
  EdgeEdgeContact c;
  if (b < a) {
    c.edge0 = edge1;
    c.edge1 = edge0;
    c.a = b;
    c.b = a;
    c.s = t;
    c.t = s;
    c.normal = -normal;
  } else {
    c.edge0 = edge0;
    c.edge1 = edge1;
    c.a = a;
    c.b = b;
    c.s = s;
    c.t = t;
    c.normal = normal;
  }
  c.distance = distance;
  return c;
}

}  // namespace crumple
