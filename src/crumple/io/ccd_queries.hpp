#pragma once
/// \file
/// Text format of narrow-phase CCD queries (`crumple ccd --queries`), one query a line:
///
///     vf  x y z (vertex) x y z (f0) x y z (f1) x y z (f2)   then the same 4 points at t = 1
///     ee  x y z (a0) x y z (a1) x y z (b0) x y z (b1)        then the same 4 points at t = 1
///
/// 24 numbers after the tag, decimal or C99 hexadecimal floats (`0x1.8p-3`), read exactly
/// (correctly rounded, std::strtod). Blank lines and lines starting with `#` are skipped.

#include <crumple/geometry/ccd.hpp>

#include <filesystem>
#include <istream>
#include <string>
#include <vector>

namespace crumple::io {

struct CcdQuery {
  geometry::CcdPair pair = geometry::CcdPair::kVertexFace;
  geometry::CcdPoints start, end;
  /// 1-based line in the file.
  std::int64_t line = 0;
};

/// Parses queries from `in`; `name` is the file name used in errors. Throws ParseError naming
/// the line and what was expected (a tag, a number, a finite number, no trailing text).
std::vector<CcdQuery> read_ccd_queries(std::istream& in, const std::string& name);
/// Same, from a file (ParseError when it cannot be opened).
std::vector<CcdQuery> read_ccd_queries(const std::filesystem::path& path);

}  // namespace crumple::io
