#include <crumple/core/error.hpp>
#include <crumple/detect/broad_phase/hash_grid.hpp>
#include <crumple/detect/broad_phase/kdop_tree.hpp>
#include <crumple/detect/broad_phase/sweep_prune.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/detect/exact_detector.hpp>
#include <crumple/detect/hybrid.hpp>
#include <crumple/detect/naive.hpp>
#include <crumple/detect/stochastic.hpp>

#include <memory>
#include <string>

namespace crumple {

std::unique_ptr<Detector> make_detector(const MethodSpec& spec, const DetectorOptions& options) {
  switch (spec.method()) {
    case Method::Naive:
      return std::make_unique<NaiveDetector>(options, spec.get_bool("cull", true));
    case Method::Kdop: {
      const KdopParams p = KdopParams::from_spec(spec);
      return std::make_unique<ExactDetector>(options, ExactParams::from_spec(spec), std::make_unique<KdopTree>(p));
    }
    case Method::Hash: {
      const HashParams p = HashParams::from_spec(spec);
      return std::make_unique<ExactDetector>(options, ExactParams::from_spec(spec), std::make_unique<HashGrid>(p));
    }
    case Method::Sap: {
      const SapParams p = SapParams::from_spec(spec);
      return std::make_unique<ExactDetector>(options, ExactParams::from_spec(spec), std::make_unique<SweepPrune>(p));
    }
    case Method::Stochastic:
      return std::make_unique<StochasticDetector>(options, StochasticParams::from_spec(spec));
    case Method::Hybrid:
      return std::make_unique<HybridDetector>(options, HybridParams::from_spec(spec));
  }
  throw InputError("no factory for method " + std::string(to_string(spec.method())));
}

}  // namespace crumple
