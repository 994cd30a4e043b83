// check_picture FILE.png [MIN_RED]: exits 0 when the PNG is not blank (at least 1% of its pixels
// differ from the corner colour, and it has at least 3 distinct colours) and holds at least
// MIN_RED (default 20) collision-red pixels (r >= 160, g <= 100, b <= 100); prints why not.
#include <support/stb_image.hpp>

#include <cstdio>
#include <cstdlib>
#include <set>

int main(int argc, char** argv) {
  if (argc < 2 || argc > 3) {
    std::fprintf(stderr, "usage: check_picture FILE.png [MIN_RED]\n");
    return 2;
  }
  const long min_red = argc == 3 ? std::strtol(argv[2], nullptr, 10) : 20;
  int w = 0, h = 0, n = 0;
  unsigned char* data = stbi_load(argv[1], &w, &h, &n, 3);
  if (data == nullptr) {
    std::fprintf(stderr, "check_picture: cannot read %s as an image: %s\n", argv[1],
                 stbi_failure_reason());
    return 1;
  }
  const unsigned char* corner = data;
  long differ = 0, red = 0;
  std::set<long> colours;
  for (long i = 0; i < static_cast<long>(w) * h; ++i) {
    const unsigned char* p = data + 3 * i;
    if (p[0] != corner[0] || p[1] != corner[1] || p[2] != corner[2]) ++differ;
    if (p[0] >= 160 && p[1] <= 100 && p[2] <= 100) ++red;
    if (colours.size() < 64) colours.insert((p[0] << 16) | (p[1] << 8) | p[2]);
  }
  stbi_image_free(data);
  std::printf(
      "check_picture: %s: %dx%d, %ld pixels differ from the background, %ld red, %zu+ colours\n",
      argv[1], w, h, differ, red, colours.size());
  if (differ * 100 < static_cast<long>(w) * h || colours.size() < 3) {
    std::fprintf(stderr, "check_picture: %s is blank\n", argv[1]);
    return 1;
  }
  if (red < min_red) {
    std::fprintf(stderr, "check_picture: %s has %ld red pixels, expected >= %ld\n", argv[1], red,
                 min_red);
    return 1;
  }
  return 0;
}
