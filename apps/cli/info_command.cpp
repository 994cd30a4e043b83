#include "commands.hpp"

#include <crumple/io/mesh_io.hpp>

#include <cstdio>
#include <iostream>
#include <memory>

namespace crumple::cli {

Run add_info_command(CLI::App& app) {
  auto file = std::make_shared<std::string>();
  app.add_option("FILE", *file, "Mesh file (.obj .ply .off .x3d)")->required();
  return [file]() {
    const TriMesh mesh = io::read_mesh(*file);
    const Topology& topo = mesh.topology();
    std::printf("file: %s\n", file->c_str());
    std::printf("vertices: %d\nfaces: %d\nedges: %d\n", topo.num_vertices(), topo.num_faces(),
                topo.num_edges());
    if (topo.num_vertices() > 0) {
      const Bounds b = compute_bounds(mesh.positions());
      std::printf("bounds min: %.9g %.9g %.9g\n", b.min.x(), b.min.y(), b.min.z());
      std::printf("bounds max: %.9g %.9g %.9g\n", b.max.x(), b.max.y(), b.max.z());
      std::printf("diagonal: %.9g\n", b.diagonal());
    }
    if (topo.num_edges() > 0) {
      const EdgeLengthStats e = edge_length_stats(topo, mesh.positions());
      std::printf("edge length min/mean/max: %.9g %.9g %.9g\n", e.min, e.mean, e.max);
    }
    std::cout << mesh.report().to_string();
    return 0;
  };
}

}  // namespace crumple::cli
