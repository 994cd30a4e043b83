#pragma once
// Results that several tests of one program compute alike (a naive reference over a frame
// sequence, a recorded simulation), computed by the first test that needs them and read back by
// the others: ctest runs every test in a process of its own, where a function-local static is
// computed again. A saved result is used only by the program file that saved it (its path, size
// and modification time head the file) and for the same key, so a rebuilt program computes
// afresh; a missing, partial or foreign file is recomputed and rewritten, never trusted. Files
// live in the folder `test-cache` beside the program, written under a temporary name and
// renamed, so that tests running at once never read half a file. Values round-trip bit for bit
// (doubles as their bytes).

#include <crumple/core/types.hpp>
#include <crumple/detect/compare.hpp>
#include <crumple/detect/contact.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/mesh/mesh.hpp>

#include <unistd.h>

#include <array>
#include <cctype>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

namespace crumple::testing {
namespace run_cache_detail {

struct Out {
  std::string bytes;
  template <class T>
    requires std::is_arithmetic_v<T>
  void put(T v) {
    char b[sizeof v];
    std::memcpy(b, &v, sizeof v);
    bytes.append(b, sizeof v);
  }
};

/// Reads what `Out` wrote; reading past the end clears `ok` and yields zeros.
struct In {
  const std::string& bytes;
  std::size_t pos = 0;
  bool ok = true;
  template <class T>
    requires std::is_arithmetic_v<T>
  T get() {
    T v{};
    if (bytes.size() - pos < sizeof v) {
      ok = false;
      return v;
    }
    std::memcpy(&v, bytes.data() + pos, sizeof v);
    pos += sizeof v;
    return v;
  }
  /// An element count, no larger than the bytes left (each element takes one at least), so a
  /// corrupt count cannot ask for more memory than the file holds.
  std::size_t count() {
    const auto n = get<std::uint64_t>();
    if (n > bytes.size() - pos) ok = false;
    return ok ? static_cast<std::size_t>(n) : 0;
  }
};

template <class T>
  requires std::is_arithmetic_v<T>
void save(Out& o, T v) {
  o.put(v);
}
template <class T>
  requires std::is_arithmetic_v<T>
void load(In& i, T& v) {
  v = i.get<T>();
}
inline void save(Out& o, const Vec3& v) {
  for (int k = 0; k < 3; ++k) o.put(v[k]);
}
inline void load(In& i, Vec3& v) {
  for (int k = 0; k < 3; ++k) v[k] = i.get<Scalar>();
}
template <class T, std::size_t N>
void save(Out& o, const std::array<T, N>& a) {
  for (const T& x : a) save(o, x);
}
template <class T, std::size_t N>
void load(In& i, std::array<T, N>& a) {
  for (T& x : a) load(i, x);
}
template <class T>
void save(Out& o, const std::vector<T>& v) {
  o.put(static_cast<std::uint64_t>(v.size()));
  for (const T& x : v) save(o, x);
}
template <class T>
void load(In& i, std::vector<T>& v) {
  v.resize(i.count());
  for (T& x : v) load(i, x);
}
inline void save(Out& o, const VertexFaceContact& c) {
  save(o, c.vertex), save(o, c.face), save(o, c.distance), save(o, c.barycentric), save(o, c.normal);
}
inline void load(In& i, VertexFaceContact& c) {
  load(i, c.vertex), load(i, c.face), load(i, c.distance), load(i, c.barycentric), load(i, c.normal);
}
inline void save(Out& o, const EdgeEdgeContact& c) {
  save(o, c.edge0), save(o, c.edge1), save(o, c.a), save(o, c.b), save(o, c.distance), save(o, c.s),
      save(o, c.t), save(o, c.normal);
}
inline void load(In& i, EdgeEdgeContact& c) {
  load(i, c.edge0), load(i, c.edge1), load(i, c.a), load(i, c.b), load(i, c.distance), load(i, c.s),
      load(i, c.t), load(i, c.normal);
}
inline void save(Out& o, const TriangleTriangleContact& c) { save(o, c.face0), save(o, c.face1); }
inline void load(In& i, TriangleTriangleContact& c) { load(i, c.face0), load(i, c.face1); }
inline void save(Out& o, const ContactSet& s) { save(o, s.vf), save(o, s.ee), save(o, s.tt); }
inline void load(In& i, ContactSet& s) { load(i, s.vf), load(i, s.ee), load(i, s.tt); }
inline void save(Out& o, const ReferenceRun& r) { save(o, r.contacts), save(o, r.ms); }
inline void load(In& i, ReferenceRun& r) { load(i, r.contacts), load(i, r.ms); }

/// What a `VectorFrames` is made of.
struct MeshFrames {
  Positions positions;  ///< the mesh's
  std::vector<Face> faces;
  std::vector<Positions> frames;
};
inline void save(Out& o, const MeshFrames& m) { save(o, m.positions), save(o, m.faces), save(o, m.frames); }
inline void load(In& i, MeshFrames& m) { load(i, m.positions), load(i, m.faces), load(i, m.frames); }

/// The running program file.
inline std::filesystem::path program() {
  std::error_code ec;
  return std::filesystem::read_symlink("/proc/self/exe", ec);
}

/// The running program file's path, size and modification time ("" when unknown: nothing is
/// then saved or read).
inline std::string program_identity() {
  std::error_code ec;
  const std::filesystem::path exe = program();
  if (exe.empty()) return "";
  const auto size = std::filesystem::file_size(exe, ec);
  if (ec) return "";
  const auto time = std::filesystem::last_write_time(exe, ec);
  if (ec) return "";
  return exe.string() + " " + std::to_string(size) + " " + std::to_string(time.time_since_epoch().count());
}

/// Where the value saved under `key` lives.
inline std::filesystem::path cache_file(const std::string& key) {
  std::string name = program().filename().string() + "-" + key;
  for (char& c : name) {
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '.') c = '_';
  }
  return program().parent_path() / "test-cache" / (name + ".bin");
}

/// `compute()`, or the value a previous run of this very program saved under `key`.
template <class T>
T cached(const std::string& key, const std::function<T()>& compute) {
  const std::string identity = program_identity();
  const std::string head = "crumple-test-cache 1\n" + identity + "\n" + key + "\n";
  const std::filesystem::path file = cache_file(key);
  if (!identity.empty()) {
    std::ifstream in(file, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (bytes.compare(0, head.size(), head) == 0) {
      In reader{bytes, head.size()};
      T value{};
      load(reader, value);
      if (reader.ok && reader.pos == bytes.size()) return value;
    }
  }
  T value = compute();
  if (!identity.empty()) {
    Out writer{head};
    save(writer, value);
    std::error_code ec;
    std::filesystem::create_directories(file.parent_path(), ec);
    const std::filesystem::path tmp = file.string() + ".tmp" + std::to_string(::getpid());
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out.write(writer.bytes.data(), static_cast<std::streamsize>(writer.bytes.size()));
    out.close();
    if (out) std::filesystem::rename(tmp, file, ec);
    std::filesystem::remove(tmp, ec);  // when the write or the rename failed
  }
  return value;
}

/// FNV-1a 64 of the bytes of every frame's positions, the mesh's faces, `h` and `kinds`, in hex.
inline std::string fingerprint(const FrameSource& frames, Scalar h, ContactKinds kinds) {
  Out o;
  save(o, h);
  save(o, static_cast<int>(kinds.vf) + 2 * static_cast<int>(kinds.ee) + 4 * static_cast<int>(kinds.tt));
  const auto faces = frames.mesh().topology().faces();
  save(o, std::vector<Face>(faces.begin(), faces.end()));
  for (std::size_t i = 0; i < frames.size(); ++i) save(o, frames.positions(i));
  std::uint64_t hash = 1469598103934665603ull;
  for (const char c : o.bytes) {
    hash ^= static_cast<unsigned char>(c);
    hash *= 1099511628211ull;
  }
  std::ostringstream s;
  s << std::hex << hash;
  return s.str();
}

}  // namespace run_cache_detail

/// `naive`'s contacts on every frame of `frames` at thickness `h` for `kinds`, computed once per
/// build of the test program (see the file comment). The key is a fingerprint of the frames, the
/// faces, `h` and `kinds`: two tests on the same input share the file, two inputs never do.
inline ReferenceRun cached_naive_reference(const FrameSource& frames, Scalar h, ContactKinds kinds = {}) {
  return run_cache_detail::cached<ReferenceRun>("naive-" + run_cache_detail::fingerprint(frames, h, kinds), [&] {
    auto naive = make_detector(MethodSpec::parse("naive"), {.thickness = h, .kinds = kinds});
    return run_reference(*naive, frames);
  });
}

/// `record()`'s mesh and frames (a recorded simulation), computed once per build of the test
/// program under `key`, which must name everything they depend on (scene spec, frames kept,
/// seed); `label` names the frames as `VectorFrames` does.
inline VectorFrames cached_frames(const std::string& key, const std::string& label,
                                  const std::function<VectorFrames()>& record) {
  const auto parts = run_cache_detail::cached<run_cache_detail::MeshFrames>("frames-" + key, [&] {
    const VectorFrames v = record();
    const auto faces = v.mesh().topology().faces();
    run_cache_detail::MeshFrames m{v.mesh().positions(), std::vector<Face>(faces.begin(), faces.end()), {}};
    for (std::size_t i = 0; i < v.size(); ++i) m.frames.push_back(v.positions(i));
    return m;
  });
  return VectorFrames(TriMesh::create(parts.positions, parts.faces), parts.frames, label);
}

}  // namespace crumple::testing
