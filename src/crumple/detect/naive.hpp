#pragma once
/// \file
/// The reference detector: the thesis' plain O(n^2) double loop over every vertex–face and
/// edge–edge pair (and face–face for TT on request), no culling of any kind (the thesis' reference loop; docs/design.md).
/// It is both the baseline of the thesis' tables and the oracle every other method is measured
/// against. The loops may run on several threads; the result does not depend on it.

#include <crumple/detect/detector.hpp>

namespace crumple {

class NaiveDetector final : public Detector {
 public:
  explicit NaiveDetector(DetectorOptions options) : Detector(options) {}
  Method method() const override { return Method::Naive; }

 protected:
  void detect(PositionsView previous, PositionsView positions, ContactSet& out) override;
};

}  // namespace crumple
