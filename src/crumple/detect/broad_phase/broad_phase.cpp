#include <crumple/core/parallel.hpp>
#include <crumple/detect/broad_phase/broad_phase.hpp>

namespace crumple {

void face_boxes(const Topology& topo, const FrameInput& in, bool sweep, std::vector<Box>& out) {
  const std::size_t nf = static_cast<std::size_t>(topo.num_faces());
  out.resize(nf);
  const bool swept = sweep && !in.previous.empty();
  parallel_for_chunks(nf, in.threads, 4096, [&](std::size_t begin, std::size_t end) {
    for (std::size_t f = begin; f < end; ++f) {
      const Face& t = topo.face(static_cast<Index>(f));
      // From the empty box, so that a NaN corner is skipped (`grow`'s minimum and maximum keep
      // the box's side), as the k-DOPs skip it: the face's finite side keeps its contacts.
      Box b = Box::empty();
      for (Index v : t) b.grow(in.positions[static_cast<std::size_t>(v)]);
      if (swept) {
        for (Index v : t) b.grow(in.previous[static_cast<std::size_t>(v)]);
      }
      b.inflate(in.radius);
      out[f] = b;
    }
  });
}

}  // namespace crumple
