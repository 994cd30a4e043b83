// `crumple render`: pictures of scenes, mesh files and frame folders; errors.
#include <crumple/io/mesh_io.hpp>
#include <crumple/mesh/shapes.hpp>
#include <support/run_cli.hpp>
#include <support/temp_dir.hpp>

#include <gtest/gtest.h>

#include <support/stb_image.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace crumple {
namespace {

using testing::run_cli;

struct Decoded {
  int width = 0, height = 0;
  long differ = 0;  ///< pixels unlike the top-left corner (the background)
  long red = 0;     ///< collision-red pixels (r >= 160, g, b <= 100)
};

Decoded decode(const std::filesystem::path& path) {
  Decoded d;
  int n = 0;
  unsigned char* data = stbi_load(path.c_str(), &d.width, &d.height, &n, 3);
  if (data == nullptr) return d;
  for (long i = 0; i < static_cast<long>(d.width) * d.height; ++i) {
    const unsigned char* p = data + 3 * i;
    d.differ += p[0] != data[0] || p[1] != data[1] || p[2] != data[2];
    d.red += p[0] >= 160 && p[1] <= 100 && p[2] <= 100;
  }
  stbi_image_free(data);
  return d;
}

TEST(Render, HangingClothInCollisionHasRedEdges) {
  const testing::TempDir dir;
  const auto png = dir / "cloth.png";
  // Frame 160 of the default hanging cloth: more than half of the edges are in collision.
  const auto r = run_cli("render hanging-cloth --frame 160 --size 320x240 --out " + png.string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("edges in collision"), std::string::npos) << r.out;
  const Decoded d = decode(png);
  EXPECT_EQ(d.width, 320);
  EXPECT_EQ(d.height, 240);
  EXPECT_GT(d.differ, 320 * 240 / 50) << "not blank";
  EXPECT_GT(d.red, 100) << "colliding edges in red";

  // At frame 0 the cloth hangs flat: nothing in collision, nothing red.
  const auto flat = dir / "flat.png";
  ASSERT_EQ(run_cli("render hanging-cloth --size 320x240 --camera 10,5 --wireframe -q --out " +
                    flat.string())
                .status,
            0);
  const Decoded f = decode(flat);
  EXPECT_GT(f.differ, 320 * 240 / 50);
  EXPECT_EQ(f.red, 0);
}

TEST(Render, MeshFileFolderAndVideo) {
  const testing::TempDir dir;
  const TriMesh folded = shapes::folded_cloth();
  io::write_obj(dir / "folded.obj", folded.positions(), folded.topology().faces());
  const auto png = dir / "folded.png";
  auto r = run_cli("render " + (dir / "folded.obj").string() +
                   " --thickness 0.02 --size 200x150 --out " + png.string());
  ASSERT_EQ(r.status, 0) << r.out;
  Decoded d = decode(png);
  EXPECT_EQ(d.width, 200);
  EXPECT_GT(d.differ, 200 * 150 / 50);
  EXPECT_GT(d.red, 20) << r.out;

  // A folder of two frames: the flat lattice, then the folded cloth; --video writes both.
  const TriMesh flat = shapes::lattice(32, 32);
  ASSERT_EQ(flat.num_vertices(), folded.num_vertices());
  const auto frames = dir / "frames";
  std::filesystem::create_directories(frames);
  io::write_obj(frames / "000.obj", flat.positions(), folded.topology().faces());
  io::write_obj(frames / "001.obj", folded.positions(), folded.topology().faces());
  const auto video = dir / "video";
  r = run_cli("render " + frames.string() + " --frame 1 --thickness 0.02 --size 160x120 --video " +
              video.string() + " --out " + (dir / "last.png").string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_TRUE(std::filesystem::exists(video / "000000.png"));
  EXPECT_TRUE(std::filesystem::exists(video / "000001.png"));
  EXPECT_EQ(decode(video / "000000.png").red, 0) << "the flat frame";
  EXPECT_GT(decode(video / "000001.png").red, 20);
  EXPECT_GT(decode(dir / "last.png").red, 20);
}

TEST(Render, BadInputsGiveAClearError) {
  const testing::TempDir dir;
  const std::string out = " --out " + (dir / "x.png").string();
  const std::vector<std::pair<std::string, std::string>> cases{
      {"render hanging-cloth --size 0x10" + out, "--size"},
      {"render hanging-cloth --size big" + out, "--size"},
      {"render hanging-cloth --camera 10" + out, "--camera"},
      {"render hanging-cloth --camera 10,abc" + out, "--camera"},
      {"render hanging-cloth --camera 10,95" + out, "pitch"},
      {"render no-such-scene" + out, "unknown scene"},
      {"render " + (dir / "missing.obj").string() + out, "no such file"},
      {"render hanging-cloth", "nothing to write"},
      {"render hanging-cloth --out " + (dir / "x.jpg").string(), ".png"},
      {"render hanging-cloth --aa 9" + out, "--aa"},
      {"render hanging-cloth --frame -1" + out, "--frame"},
      {"render " + dir.path().string() + out, "no .obj"},
  };
  for (const auto& [args, needle] : cases) {
    const auto r = run_cli(args);
    EXPECT_EQ(r.status, 1) << args << "\n" << r.out;
    EXPECT_NE(r.out.find("error"), std::string::npos) << args << "\n" << r.out;
    EXPECT_NE(r.out.find(needle), std::string::npos) << args << "\n" << r.out;
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "x.png"));
}

/// `text` quoted for the test's own shell (the command line that starts crumple).
std::string shell_quote(const std::string& text) {
  std::string out = "'";
  for (char c : text) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

// A --video folder whose name holds a quote and a command substitution: ffmpeg (a fake one that
// records its arguments and folder) gets the names as plain arguments and nothing is executed.
TEST(Render, VideoFolderNameIsNeverRunAsACommand) {
  const testing::TempDir dir;
  const auto bin = dir / "bin";
  std::filesystem::create_directories(bin);
  const auto record = dir / "ffmpeg-args.txt";
  {
    std::ofstream fake(bin / "ffmpeg");
    fake << "#!/bin/sh\npwd > " << shell_quote(record.string()) << "\n"
         << "for a in \"$@\"; do printf '%s\\n' \"$a\"; done >> " << shell_quote(record.string())
         << "\n";
  }
  std::filesystem::permissions(bin / "ffmpeg", std::filesystem::perms::owner_all);
  const std::string video = "v'$(touch PWNED)'`touch PWNED2`";
  const auto r = testing::run_program(
      "cd " + shell_quote(dir.path().string()) + " && PATH=" + shell_quote(bin.string()) +
          ":\"$PATH\" " + CRUMPLE_CLI,
      "render hanging-cloth:nx=4,ny=4 --frame 1 --size 40x30 --video " + shell_quote(video));
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_FALSE(std::filesystem::exists(dir / "PWNED")) << "a shell ran the folder's name";
  EXPECT_FALSE(std::filesystem::exists(dir / "PWNED2")) << "a shell ran the folder's name";
  EXPECT_TRUE(std::filesystem::exists(dir / video / "000001.png"));
  const std::vector<std::string> lines = testing::read_lines(record);
  ASSERT_FALSE(lines.empty()) << "the fake ffmpeg did not run\n" << r.out;
  EXPECT_EQ(std::filesystem::path(lines[0]), std::filesystem::canonical(dir / video));
  EXPECT_EQ(lines.back(), "video.mp4");
  EXPECT_NE(std::find(lines.begin(), lines.end(), "[0-9][0-9][0-9][0-9][0-9][0-9].png"),
            lines.end());
}

}  // namespace
}  // namespace crumple
