#include <crumple/core/atomic_file.hpp>
#include <crumple/core/error.hpp>
#include <crumple/detect/contact.hpp>

#include <algorithm>
#include <charconv>

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

void ContactSet::sort() {
  const auto sort_list = [](auto& v) {
    if (!std::is_sorted(v.begin(), v.end(), CanonicalLess{})) std::sort(v.begin(), v.end(), CanonicalLess{});
  };
  sort_list(vf);
  sort_list(ee);
  sort_list(tt);
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

}  // namespace crumple
