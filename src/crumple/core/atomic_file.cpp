#include <crumple/core/atomic_file.hpp>
#include <crumple/core/error.hpp>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <ostream>
#include <streambuf>
#include <string>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace crumple {

namespace {

namespace fs = std::filesystem;

std::string os_reason(int error) { return std::strerror(error); }

/// Unbuffered-by-the-OS output to a file descriptor that remembers the first failed write
/// (after which it drops what it is given, so a full disk fails once, quickly).
class FdBuffer : public std::streambuf {
 public:
  explicit FdBuffer(int fd) : fd_(fd), buffer_(std::size_t{1} << 16) { reset(); }
  /// errno of the first failed write, 0 when none failed.
  int error() const { return error_; }

 protected:
  int_type overflow(int_type ch) override {
    if (!drain()) return traits_type::eof();
    if (!traits_type::eq_int_type(ch, traits_type::eof())) {
      *pptr() = traits_type::to_char_type(ch);
      pbump(1);
    }
    return traits_type::not_eof(ch);
  }
  int sync() override { return drain() ? 0 : -1; }

 private:
  void reset() { setp(buffer_.data(), buffer_.data() + buffer_.size()); }
  bool drain() {
    const char* p = pbase();
    auto left = static_cast<std::size_t>(pptr() - pbase());
    reset();
    while (error_ == 0 && left > 0) {
      const ::ssize_t n = ::write(fd_, p, left);
      if (n < 0) {
        if (errno != EINTR) error_ = errno;
        continue;
      }
      p += n;
      left -= static_cast<std::size_t>(n);
    }
    return error_ == 0;
  }
  int fd_;
  std::vector<char> buffer_;
  int error_ = 0;
};

fs::path temporary_name(const fs::path& path) {
  static std::atomic<unsigned> counter{0};
  // Built with append: `"." + std::string` chains trip a GCC 12 -Wrestrict false positive.
  std::string name(".");
  name.append(path.filename().string())
      .append(".tmp.")
      .append(std::to_string(::getpid()))
      .append(".")
      .append(std::to_string(counter.fetch_add(1)));
  return path.parent_path() / name;
}

std::string kind_of(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISFIFO(mode)) return "a FIFO (named pipe)";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a regular file";
}

}  // namespace

void write_file_atomically(const fs::path& path, const std::function<void(std::ostream&)>& write,
                           bool /*binary: POSIX files have no text mode*/) {
  const auto refuse = [&](const std::string& why) { throw ParseError(path.string(), {}, why); };
  if (path.empty()) refuse("empty output path");
  // The file a write lands in: the end of the chain of symbolic links (the links stay).
  fs::path target = path;
  for (int hops = 0;; ++hops) {
    struct stat link {};
    if (::lstat(target.c_str(), &link) != 0 || !S_ISLNK(link.st_mode)) break;
    if (hops == 40) refuse("too many levels of symbolic links");
    std::error_code ec;
    const fs::path next = fs::read_symlink(target, ec);
    if (ec) refuse("cannot read the symbolic link " + target.string() + ": " + ec.message());
    target = next.is_absolute() ? next : target.parent_path() / next;
  }
  const std::string via = target == path ? std::string() : " (the target of the link, " + target.string() + ")";
  struct stat existing {};
  const bool exists = ::stat(target.c_str(), &existing) == 0;
  if (exists && !S_ISREG(existing.st_mode)) {
    refuse("is " + kind_of(existing.st_mode) + via + ", not a regular file: refusing to replace it");
  }
  if (!exists && errno != ENOENT) refuse("cannot write here" + via + ": " + os_reason(errno));
  if (target.filename().empty()) refuse("names a folder, not a file");

  const fs::path tmp = temporary_name(target);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd < 0) {
    const fs::path dir = target.parent_path().empty() ? fs::path(".") : target.parent_path();
    refuse("cannot create a file in " + dir.string() + ": " + os_reason(errno));
  }
  const auto fail = [&](const std::string& what) {
    ::close(fd);
    ::unlink(tmp.c_str());
    refuse(what);
  };
  // A replaced file keeps its permission bits.
  if (exists && ::fchmod(fd, existing.st_mode & 07777) != 0) fail("cannot set permissions: " + os_reason(errno));
  FdBuffer buffer(fd);
  {
    std::ostream out(&buffer);
    try {
      write(out);
    } catch (...) {
      ::close(fd);
      ::unlink(tmp.c_str());
      throw;
    }
    out.flush();
  }
  if (buffer.error() != 0) fail("write failed" + via + ": " + os_reason(buffer.error()));
  if (::fsync(fd) != 0) fail("write failed (fsync)" + via + ": " + os_reason(errno));
  if (::close(fd) != 0) {
    const int error = errno;
    ::unlink(tmp.c_str());
    refuse("write failed (close)" + via + ": " + os_reason(error));
  }
  if (::rename(tmp.c_str(), target.c_str()) != 0) {
    const int error = errno;
    ::unlink(tmp.c_str());
    refuse("cannot rename the temporary file into place" + via + ": " + os_reason(error));
  }
}

}  // namespace crumple
