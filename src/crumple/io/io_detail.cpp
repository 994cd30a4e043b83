#include <crumple/core/atomic_file.hpp>
#include <crumple/io/io_detail.hpp>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <memory>
#include <system_error>

namespace crumple::io::detail {

std::string read_whole_file(const std::filesystem::path& path) {
  const auto system_reason = [](int err) { return std::generic_category().message(err); };
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    fail_in_file(path, "cannot read the file: it is a directory");
  }
  errno = 0;
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> file(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!file) {
    fail_in_file(path, "cannot open the file for reading: " + system_reason(errno));
  }
  // Read in chunks until the end (the size on disk is only a hint: the file may change, or be
  // a pipe); reserving size + one chunk makes a regular file one allocation.
  constexpr std::size_t chunk = std::size_t{1} << 20;
  std::string bytes;
  std::error_code size_ec;
  const auto size = std::filesystem::file_size(path, size_ec);
  if (!size_ec && size < (std::uintmax_t{1} << 40)) bytes.reserve(static_cast<std::size_t>(size) + chunk);
  std::size_t used = 0;
  for (;;) {
    bytes.resize(used + chunk);
    const std::size_t got = std::fread(bytes.data() + used, 1, chunk, file.get());
    used += got;
    if (got < chunk) break;
  }
  bytes.resize(used);
  if (std::ferror(file.get())) {
    fail_in_file(path, "cannot read the file: " + system_reason(errno ? errno : EIO));
  }
  return bytes;
}

void fail_at_line(const std::filesystem::path& path, std::int64_t line, const std::string& message) {
  throw ParseError(path.string(), {.line = line, .byte_offset = std::nullopt}, message);
}

void fail_at_byte(const std::filesystem::path& path, std::int64_t offset,
                  const std::string& message) {
  throw ParseError(path.string(), {.line = std::nullopt, .byte_offset = offset}, message);
}

void fail_in_file(const std::filesystem::path& path, const std::string& message) {
  throw ParseError(path.string(), {}, message);
}

std::optional<std::string> repeated_vertex(const Face& t, std::int64_t base) {
  Index twice = -1;
  if (t[0] == t[1] || t[0] == t[2]) twice = t[0];
  else if (t[1] == t[2]) twice = t[1];
  if (twice < 0) return std::nullopt;
  return "triangle " + std::to_string(t[0] + base) + " " + std::to_string(t[1] + base) + " " +
         std::to_string(t[2] + base) + " repeats vertex " + std::to_string(twice + base) +
         " (a face needs distinct vertices)";
}

std::string quote(std::string_view token) {
  constexpr std::size_t max_chars = 40;
  std::string out = "'";
  const std::size_t n = std::min(token.size(), max_chars);
  for (std::size_t i = 0; i < n; ++i) {
    const auto c = static_cast<unsigned char>(token[i]);
    if (c >= 0x20 && c < 0x7f) {
      out += static_cast<char>(c);
    } else {
      constexpr const char* hex = "0123456789ABCDEF";
      out += "\\x";
      out += hex[c >> 4];
      out += hex[c & 15];
    }
  }
  if (token.size() > max_chars) out += "...";
  out += "'";
  return out;
}

std::optional<double> to_double(std::string_view token) {
  if (!token.empty() && token.front() == '+') {
    token.remove_prefix(1);
    if (!token.empty() && (token.front() == '-' || token.front() == '+')) return std::nullopt;
  }
  if (token.empty()) return std::nullopt;
  double value = 0;
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, value);
  if (ptr != end) return std::nullopt;
  if (ec == std::errc::result_out_of_range) {
    // from_chars leaves the value alone on underflow and overflow; strtod gives the rounded
    // result (0 or a subnormal on underflow, +-HUGE_VAL on overflow). The token is known to be a
    // well-formed number here, so strtod consumes all of it.
    const std::string copy(token);
    return std::strtod(copy.c_str(), nullptr);
  }
  if (ec != std::errc()) return std::nullopt;
  return value;
}

std::optional<std::int64_t> to_int(std::string_view token) {
  if (!token.empty() && token.front() == '+') {
    token.remove_prefix(1);
    if (!token.empty() && (token.front() == '-' || token.front() == '+')) return std::nullopt;
  }
  if (token.empty()) return std::nullopt;
  std::int64_t value = 0;
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, value);
  if (ec != std::errc() || ptr != end) return std::nullopt;
  return value;
}

void append_double(std::string& out, double value) {
  char buffer[64];
  const auto [ptr, ec] = std::to_chars(buffer, buffer + sizeof buffer, value);
  CRUMPLE_ASSERT(ec == std::errc());
  (void)ec;
  out.append(buffer, ptr);
}

void append_int(std::string& out, std::int64_t value) {
  char buffer[32];
  const auto [ptr, ec] = std::to_chars(buffer, buffer + sizeof buffer, value);
  CRUMPLE_ASSERT(ec == std::errc());
  (void)ec;
  out.append(buffer, ptr);
}

void Tokens::skip_separators() {
  while (pos_ < text_.size() && is_separator(text_[pos_])) ++pos_;
}

std::optional<std::string_view> Tokens::next() {
  skip_separators();
  if (pos_ >= text_.size()) return std::nullopt;
  const std::size_t start = pos_;
  while (pos_ < text_.size() && !is_separator(text_[pos_])) ++pos_;
  return text_.substr(start, pos_ - start);
}

bool Tokens::at_end() {
  skip_separators();
  return pos_ >= text_.size();
}

std::optional<std::string_view> LineReader::next_physical() {
  if (pos_ >= text_.size()) return std::nullopt;
  const std::size_t start = pos_;
  const std::size_t newline = text_.find('\n', start);
  const std::size_t end = newline == std::string_view::npos ? text_.size() : newline;
  pos_ = newline == std::string_view::npos ? text_.size() : newline + 1;
  ++lines_read_;
  return text_.substr(start, end - start);
}

namespace {
// Position of a continuation backslash (the last non-blank character), or npos.
std::size_t continuation_mark(std::string_view line) {
  std::size_t end = line.size();
  while (end > 0 && is_blank(line[end - 1])) --end;
  if (end > 0 && line[end - 1] == '\\') return end - 1;
  return std::string_view::npos;
}
}  // namespace

std::optional<std::string_view> LineReader::next() {
  auto line = next_physical();
  if (!line) return std::nullopt;
  line_number_ = lines_read_;
  if (!continuation_) return line;
  std::size_t mark = continuation_mark(*line);
  if (mark == std::string_view::npos) return line;
  joined_.assign(line->substr(0, mark));
  joined_ += ' ';
  while (auto more = next_physical()) {
    mark = continuation_mark(*more);
    if (mark == std::string_view::npos) {
      joined_.append(*more);
      break;
    }
    joined_.append(more->substr(0, mark));
    joined_ += ' ';
  }
  return std::string_view(joined_);
}

std::string_view strip_comment(std::string_view line, char marker) {
  const std::size_t at = line.find(marker);
  return at == std::string_view::npos ? line : line.substr(0, at);
}

std::int64_t line_of_offset(std::string_view text, std::size_t offset) {
  offset = std::min(offset, text.size());
  std::int64_t line = 1;
  for (std::size_t i = 0; i < offset; ++i) line += text[i] == '\n' ? 1 : 0;
  return line;
}

void check_mesh_for_writing(PositionsView positions, std::span<const Face> faces) {
  constexpr auto max_index = static_cast<std::size_t>(std::numeric_limits<Index>::max());
  CRUMPLE_CHECK(positions.size() <= max_index, "too many vertices for Index");
  CRUMPLE_CHECK(faces.size() <= max_index, "too many faces for Index");
  for (std::size_t v = 0; v < positions.size(); ++v) {
    CRUMPLE_CHECK(positions[v].allFinite(),
                  "vertex " + std::to_string(v) + " has a non-finite coordinate");
  }
  const auto nv = static_cast<Index>(positions.size());
  for (std::size_t f = 0; f < faces.size(); ++f) {
    for (const Index id : faces[f]) {
      CRUMPLE_CHECK(id >= 0 && id < nv, "face " + std::to_string(f) + " has vertex id " +
                                            std::to_string(id) + " outside [0, " +
                                            std::to_string(nv) + ")");
    }
  }
}

void append_position_lines(std::string& out, std::string_view prefix, PositionsView positions) {
  for (const Vec3& p : positions) {
    out += prefix;
    append_double(out, p.x());
    out += ' ';
    append_double(out, p.y());
    out += ' ';
    append_double(out, p.z());
    out += '\n';
  }
}

void append_face_lines(std::string& out, std::string_view prefix, std::span<const Face> faces,
                       std::int64_t id_offset) {
  for (const Face& f : faces) {
    out += prefix;
    append_int(out, std::int64_t{f[0]} + id_offset);
    out += ' ';
    append_int(out, std::int64_t{f[1]} + id_offset);
    out += ' ';
    append_int(out, std::int64_t{f[2]} + id_offset);
    out += '\n';
  }
}

void write_string_atomically(const std::filesystem::path& path, const std::string& content,
                             bool binary) {
  write_file_atomically(
      path,
      [&](std::ostream& stream) {
        stream.write(content.data(), static_cast<std::streamsize>(content.size()));
      },
      binary);
}

}  // namespace crumple::io::detail
