// libFuzzer target: one mesh reader (CRUMPLE_FUZZ_EXT names its format), then the validation and
// topology build of `read_mesh`, then one exact detection (kdop) at the default thickness.
// Errors crumple throws by design for bad input (ParseError, InputError, a contact overflow) are
// expected outcomes; a PreconditionError means the library broke its own contract and aborts,
// like any other exception, crash, sanitizer report, timeout or out-of-memory (all findings).
// See docs/fuzzing.md.

#include <crumple/core/error.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/detect/method.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/mesh/mesh.hpp>

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <string>

#ifndef CRUMPLE_FUZZ_EXT
#error "CRUMPLE_FUZZ_EXT must name the reader's file extension, e.g. \"obj\""
#endif

namespace {

// Detection runs only on meshes up to this many faces, so that a valid but large input cannot
// time out the fuzzer (its work grows with the contacts, which a fuzzed mesh can make dense).
constexpr crumple::Index kMaxDetectFaces = 4096;
// Contacts beyond this are dropped (overflow=truncate), bounding the output's memory.
constexpr const char* kSpec = "kdop:max_contacts=200000,overflow=truncate";

// The readers take paths: each input is written to one file per process (RAM disk if present).
const std::filesystem::path& input_path() {
  static const std::filesystem::path path = [] {
    std::error_code ec;
    std::filesystem::path dir = "/dev/shm";
    if (!std::filesystem::is_directory(dir, ec)) dir = std::filesystem::temp_directory_path();
    return dir / ("crumple-fuzz-" + std::to_string(::getpid()) + "." CRUMPLE_FUZZ_EXT);
  }();
  return path;
}

[[noreturn]] void finding(const char* what) {
  std::fprintf(stderr, "crumple fuzz finding: %s\n", what);
  std::abort();
}

void run(const std::uint8_t* data, std::size_t size) {
  {
    std::ofstream out(input_path(), std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
    if (!out.flush()) finding("cannot write the input file");
  }
  const crumple::TriMesh mesh = crumple::io::read_mesh(input_path());
  if (mesh.num_faces() > kMaxDetectFaces) return;
  crumple::DetectorOptions options;
  options.thickness = crumple::default_thickness(mesh.positions());
  options.threads = 1;
  auto detector = crumple::make_detector(crumple::MethodSpec::parse(kSpec), options);
  detector->set_topology(mesh.topology_ptr());
  crumple::ContactSet contacts;
  detector->update(mesh.positions(), contacts);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    run(data, size);
  } catch (const crumple::PreconditionError& e) {
    finding(e.what());
  } catch (const crumple::Error&) {
    // A rejected input: the expected outcome for malformed or invalid meshes.
  } catch (const std::exception& e) {
    finding(e.what());
  }
  return 0;
}
