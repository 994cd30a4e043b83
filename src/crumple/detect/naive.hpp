#pragma once
/// \file
/// The reference detector: the thesis' plain O(n^2) double loop over every vertex–face and
/// edge–edge pair (and face–face for TT on request; docs/design.md). It is the oracle every other
/// method is measured against and, with `cull=off`, the baseline of the thesis' tables. With the
/// cull (the default) a pair goes through the exact test unless its bounding boxes, padded by the
/// thickness plus a margin far above any rounding of the computed distance, are apart on an axis:
/// such a pair is farther than the thickness, so the contacts are those of the plain loop. The
/// loops may run on several threads; the result does not depend on it.

#include <crumple/detect/detector.hpp>

namespace crumple {

class NaiveDetector final : public Detector {
 public:
  explicit NaiveDetector(DetectorOptions options, bool cull = true) : Detector(options), cull_(cull) {}
  Method method() const override { return Method::Naive; }

 protected:
  void detect(PositionsView previous, PositionsView positions, ContactSet& out) override;

 private:
  bool cull_;
};

}  // namespace crumple
