#include <crumple/io/ccd_queries.hpp>

#include <crumple/core/error.hpp>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace crumple::io {

std::vector<CcdQuery> read_ccd_queries(std::istream& in, const std::string& name) {
  std::vector<CcdQuery> queries;
  std::string text;
  std::int64_t line = 0;
  while (std::getline(in, text)) {
    ++line;
    if (!text.empty() && text.back() == '\r') text.pop_back();
    std::istringstream tokens(text);
    std::string tag;
    if (!(tokens >> tag) || tag[0] == '#') continue;
    const auto fail = [&](const std::string& what) { throw ParseError(name, {line, {}}, what); };
    CcdQuery q;
    q.line = line;
    if (tag == "vf") {
      q.pair = geometry::CcdPair::kVertexFace;
    } else if (tag == "ee") {
      q.pair = geometry::CcdPair::kEdgeEdge;
    } else {
      fail("expected 'vf' or 'ee' at the start of the line, got '" + tag + "'");
    }
    for (int i = 0; i < 24; ++i) {
      std::string word;
      if (!(tokens >> word)) {
        fail("expected 24 numbers after '" + tag + "', got " + std::to_string(i));
      }
      char* end = nullptr;
      const double value = std::strtod(word.c_str(), &end);
      if (end == word.c_str() || *end != '\0') fail("number " + std::to_string(i + 1) + " is not a number: '" + word + "'");
      if (!std::isfinite(value)) {
        fail("number " + std::to_string(i + 1) + " is not a finite double: '" + word + "'");
      }
      geometry::CcdPoints& points = i < 12 ? q.start : q.end;
      points[(i % 12) / 3][i % 3] = value;
    }
    std::string extra;
    if (tokens >> extra) fail("expected the end of the line after 24 numbers, got '" + extra + "'");
    queries.push_back(q);
  }
  return queries;
}

std::vector<CcdQuery> read_ccd_queries(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw ParseError(path.string(), {}, "cannot open the query file");
  return read_ccd_queries(in, path.string());
}

}  // namespace crumple::io
