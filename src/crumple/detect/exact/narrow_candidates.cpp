#include <crumple/core/parallel.hpp>
#include <crumple/detect/exact/narrow_frame.hpp>

#include <algorithm>
#include <array>
#include <span>
#include <type_traits>

namespace crumple::exact {

namespace {

/// The vertex-face sub-pairs of a candidate face pair, indexed by `mask_a | mask_b << 3` (bit k
/// of each: the face owns corner k, and it lies in the other face's box): codes `side << 2 | k`
/// (side 0: corner k of the first face against the second face; side 1: the other way round),
/// with their counts. Unused codes are 0. The codes are 16-bit and the rows padded to 8, so that
/// listing a candidate's codes is one vector operation (8-bit codes, widened one by one, cost a
/// stall each).
struct VertexFaceTable {
  std::array<std::array<std::uint16_t, 8>, 64> codes{};
  std::array<std::uint8_t, 64> count{};
  constexpr VertexFaceTable() {
    for (unsigned key = 0; key < 64; ++key) {
      const unsigned ma = key & 7u, mb = key >> 3;
      unsigned n = 0;
      for (unsigned k = 0; k < 3; ++k) {
        if (ma >> k & 1u) codes[key][n++] = static_cast<std::uint16_t>(k);
        if (mb >> k & 1u) codes[key][n++] = static_cast<std::uint16_t>(4u | k);
      }
      count[key] = static_cast<std::uint8_t>(n);
    }
  }
};
constexpr VertexFaceTable kVertexFace{};

/// The edge-edge sub-pairs of a candidate face pair, indexed by a 9-bit mask (bit 3i + j: side i
/// of the first face and side j of the second are both owned and their boxes meet): codes
/// `i << 2 | j`, with their counts, rows padded to 16 as above.
struct EdgeEdgeTable {
  std::array<std::array<std::uint16_t, 16>, 512> codes{};
  std::array<std::uint8_t, 512> count{};
  constexpr EdgeEdgeTable() {
    for (unsigned m = 0; m < 512; ++m) {
      unsigned n = 0;
      for (unsigned b = 0; b < 9; ++b) {
        if (m >> b & 1u) codes[m][n++] = static_cast<std::uint16_t>((b / 3) << 2 | b % 3);
      }
      count[m] = static_cast<std::uint8_t>(n);
    }
  }
};
constexpr EdgeEdgeTable kEdgeEdge{};

/// A block's candidate: the two faces, and where their corners are in x (looked up once).
struct Candidate {
  std::array<const PackedFace*, 2> face;
  std::array<std::array<const Vec3*, 3>, 2> at;
};

/// Codes of a block's sub-pairs: the candidate's place in the block << 4 | the table's code.
/// Room for a full table row written past the last candidate's codes.
struct BlockCodes {
  std::array<std::uint16_t, kBlock * 6 + 8> vf;
  std::array<std::uint16_t, kBlock * 9 + 16> ee;
  std::size_t nvf = 0, nee = 0;
};

/// Side k joins corners k and kNext[k].
constexpr std::array<std::size_t, 3> kNext{1, 2, 0};

/// Lists a block of candidates starting at candidate `i` of chunk `c` (at most kBlock, up to
/// `end`), and the owned sub-pairs of each whose boxes meet (`coarse_masks`: all of a pair's
/// box tests in a few float-lane operations), from the tables without a branch. Returns the
/// number of candidates listed; advances i and c.
template <class Chunks>
std::size_t list_block(const NarrowFrame& frame, const Chunks& chunks,
                       std::span<const std::size_t> offsets, std::size_t& i, std::size_t& c, std::size_t end,
                       std::array<Candidate, kBlock>& block, BlockCodes& codes) {
  const std::vector<PackedFace>& packed = frame.packed;
  const ContactKinds kinds = frame.kinds;
  const auto corner = [&](const PackedFace& t, std::size_t k) -> const Vec3& { return frame.corner(t, k); };
  const auto axes = [&](const PackedFace& t) {
    return coarse_axes(frame.coarse_point(t.v[0]), frame.coarse_point(t.v[1]), frame.coarse_point(t.v[2]));
  };
  std::size_t n = 0;
  codes.nvf = codes.nee = 0;
  for (; i < end && n < kBlock; ++i, ++n) {
    while (i >= offsets[c + 1]) ++c;
    const FacePair& pair = chunks[c][i - offsets[c]];
    if (const std::size_t ahead = i + kBlock - offsets[c]; ahead < chunks[c].size()) {
      // The records of the next block's candidates, read while this block is processed.
      for (const Index f : chunks[c][ahead]) {
        __builtin_prefetch(&packed[static_cast<std::size_t>(f)]);
        if (kinds.tt) {
          const auto* r = reinterpret_cast<const char*>(&frame.face_corners[static_cast<std::size_t>(f)]);
          __builtin_prefetch(r);
          __builtin_prefetch(r + sizeof(frame.face_corners[0]) - 1);
        }
      }
    }
    const PackedFace& a = packed[static_cast<std::size_t>(pair[0])];
    const PackedFace& b = packed[static_cast<std::size_t>(pair[1])];
    block[n].face = {&a, &b};
    block[n].at = {{{&corner(a, 0), &corner(a, 1), &corner(a, 2)}, {&corner(b, 0), &corner(b, 1), &corner(b, 2)}}};
    const auto base = static_cast<std::uint16_t>(n << 4);
    const CoarseMasks box =
        frame.proximity ? coarse_masks(axes(a), axes(b), frame.float_half_pad, frame.float_pad) : CoarseMasks{};
    if (kinds.vf) {
      const unsigned vkey = (a.vertex_mask | static_cast<unsigned>(b.vertex_mask) << 3) & box.vf;
      for (std::size_t k = 0; k < 8; ++k) {
        codes.vf[codes.nvf + k] = static_cast<std::uint16_t>(base | kVertexFace.codes[vkey][k]);
      }
      codes.nvf += kVertexFace.count[vkey];
    }
    if (kinds.ee) {
      // Bit 3i + j: side i of a and side j of b are both owned (b's mask, repeated at bits
      // 0, 3 and 6 where a owns side 0, 1, 2).
      const unsigned spread = (a.edge_mask & 1u) | (a.edge_mask & 2u) << 2 | (a.edge_mask & 4u) << 4;
      const unsigned ekey = (spread * b.edge_mask) & box.ee;
      for (std::size_t k = 0; k < 16; ++k) {
        codes.ee[codes.nee + k] = static_cast<std::uint16_t>(base | kEdgeEdge.codes[ekey][k]);
      }
      codes.nee += kEdgeEdge.count[ekey];
    }
  }
  return n;
}

/// VF: corner (code & 3) of one face of the pair (the first, or with bit 2 the second),
/// against the other face.
void block_vertex_face(const NarrowFrame& frame, const std::array<Candidate, kBlock>& block, BlockCodes& codes,
                       LocalContacts& local) {
  const std::size_t nvf = frame.sift_separated<false>(codes.vf.data(), codes.nvf, [&](std::uint16_t code) {
    const Candidate& m = block[code >> 4];
    const std::size_t from = code >> 2 & 1u;
    const auto& t = m.at[from ^ 1u];
    return geometry::SeparationPoints{m.at[from][code & 3u], t[0], t[1], t[2]};
  });
  const PackedFace* packed = frame.packed.data();
  for (std::size_t s = 0; s < nvf; ++s) {
    const Candidate& m = block[codes.vf[s] >> 4];
    const std::size_t from = codes.vf[s] >> 2 & 1u, k = codes.vf[s] & 3u;
    const PackedFace* t = m.face[from ^ 1u];
    const auto& at = m.at[from ^ 1u];
    frame.vf_kernel(*m.at[from][k], m.face[from]->v[k], *at[0], *at[1], *at[2], static_cast<Index>(t - packed), local);
  }
}

/// EE: side i of the first face against side j of the second (code i << 2 | j).
void block_edge_edge(const NarrowFrame& frame, const std::array<Candidate, kBlock>& block, BlockCodes& codes,
                     LocalContacts& local) {
  // Their ends, as corners of each face.
  const auto ends = [](std::uint16_t code) {
    const std::size_t i2 = code >> 2 & 3u, j = code & 3u;
    return std::array<std::size_t, 4>{i2, kNext[i2], j, kNext[j]};
  };
  const std::size_t nee = frame.sift_separated<true>(codes.ee.data(), codes.nee, [&](std::uint16_t code) {
    const auto& at = block[code >> 4].at;
    const auto k = ends(code);
    return geometry::SeparationPoints{at[0][k[0]], at[0][k[1]], at[1][k[2]], at[1][k[3]]};
  });
  for (std::size_t s = 0; s < nee; ++s) {
    const Candidate& m = block[codes.ee[s] >> 4];
    const PackedFace &a = *m.face[0], &b = *m.face[1];
    const auto k = ends(codes.ee[s]);
    frame.ee_kernel(*m.at[0][k[0]], *m.at[0][k[1]], a.v[k[0]], a.v[k[1]], a.e[k[0]], *m.at[1][k[2]], *m.at[1][k[3]],
                    b.v[k[2]], b.v[k[3]], b.e[k[2]], local);
  }
}

/// TT: every candidate of the block, with no box test first: a broad phase's candidates have
/// boxes that overlap once padded.
void block_triangle_triangle(const NarrowFrame& frame, const std::array<Candidate, kBlock>& block, std::size_t n,
                             LocalContacts& local) {
  const PackedFace* packed = frame.packed.data();
  for (std::size_t m = 0; m < n; ++m) {
    const PackedFace& a = *block[m].face[0];
    const PackedFace& b = *block[m].face[1];
    const auto f = static_cast<Index>(&a - packed), g = static_cast<Index>(&b - packed);
    ++local.tt_tests;
    const std::array<Vec3, 3>& pa = frame.face_corners[static_cast<std::size_t>(f)];
    const std::array<Vec3, 3>& pb = frame.face_corners[static_cast<std::size_t>(g)];
    if (f < g) {
      local.tt_batch.push(f, pa, g, pb, local.set.tt);
    } else {
      local.tt_batch.push(g, pb, f, pa, local.set.tt);
    }
    frame.spill(local);
  }
}

/// The sub-pairs of candidates [i, end) of the chunks, listed and tested block by block.
template <class Chunks>
void narrow_range(const NarrowFrame& frame, const Chunks& chunks, std::span<const std::size_t> offsets,
                  std::size_t i, std::size_t end, LocalContacts& local) {
  std::array<Candidate, kBlock> block;
  BlockCodes codes;
  std::size_t c = static_cast<std::size_t>(std::upper_bound(offsets.begin(), offsets.end(), i) - offsets.begin() - 1);
  while (i < end) {
    const std::size_t n = list_block(frame, chunks, offsets, i, c, end, block, codes);
    if (frame.kinds.vf) block_vertex_face(frame, block, codes, local);
    if (frame.kinds.ee) block_edge_edge(frame, block, codes, local);
    if (frame.kinds.tt) block_triangle_triangle(frame, block, n, local);
  }
}

}  // namespace

bool narrow_candidates(NarrowFrame& frame, std::span<const FacePair> chunk, Cutoff& cut) {
  const std::array<std::span<const FacePair>, 1> chunks{chunk};
  const std::array<std::size_t, 2> offsets{0, chunk.size()};
  LocalContacts local{frame.spares.take()};
  bool complete = true;
  for (std::size_t i = 0; i < chunk.size();) {
    const std::size_t n = cut.claim(std::min(kBlock, chunk.size() - i));
    if (n == 0) {
      complete = false;
      break;
    }
    narrow_range(frame, chunks, offsets, i, i + n, local);
    i += n;
  }
  frame.collect(local);
  return complete;
}

void narrow_candidates(NarrowFrame& frame, const CandidateBuffer& candidates) {
  const auto& chunks = candidates.chunks();
  std::vector<std::size_t> offsets(chunks.size() + 1, 0);
  for (std::size_t i = 0; i < chunks.size(); ++i) offsets[i + 1] = offsets[i] + chunks[i].size();
  const std::size_t total = offsets.back();
  // Chunks of 2,048 candidates, or fewer so that each thread has at least 16
  // (`balanced_grain`): a small scene's chunks would otherwise leave a thread idle at the end.
  const std::size_t grain = balanced_grain(total, frame.threads, 256, 2048);
  parallel_for_chunks(total, frame.threads, grain, [&](std::size_t begin, std::size_t end) {
    LocalContacts local{frame.spares.take()};
    narrow_range(frame, chunks, offsets, begin, end, local);
    frame.collect(local);
  });
}

void narrow_candidate_chunk(NarrowFrame& frame, std::span<const FacePair> chunk) {
  if (chunk.empty()) return;
  const std::array<std::span<const FacePair>, 1> chunks{chunk};
  const std::array<std::size_t, 2> offsets{0, chunk.size()};
  LocalContacts local{frame.spares.take()};
  narrow_range(frame, chunks, offsets, 0, chunk.size(), local);
  frame.collect(local);
}

}  // namespace crumple::exact
