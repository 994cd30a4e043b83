// `crumple ccd --queries FILE`: the narrow-phase CCD on a file of queries, one answer a line.
#include "commands.hpp"

#include <crumple/geometry/ccd.hpp>
#include <crumple/io/ccd_queries.hpp>

#include <cstdio>
#include <map>
#include <memory>
#include <string>

namespace crumple::cli {

namespace {
struct CcdArgs {
  std::string queries;
  double min_separation = 0;
  double time_tolerance = 1e-6;
  long long max_boxes = 10000;
  bool stats = false;
};
}  // namespace

Run add_ccd_command(CLI::App& app) {
  auto args = std::make_shared<CcdArgs>();
  app.add_option("--queries", args->queries,
                 "Query file: per line 'vf' or 'ee' then the 4 points at t=0 and at t=1 (24 numbers, "
                 "decimal or hex floats). Prints '1 TOI' or '0' per query")
      ->required();
  app.add_option("--min-separation", args->min_separation, "Minimum separation delta >= 0 (default 0)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--time-tolerance", args->time_tolerance, "Time tolerance of the reported TOI (default 1e-6)")
      ->check(CLI::PositiveNumber);
  app.add_option("--max-boxes", args->max_boxes, "Box budget per query before a conservative hit (default 10000)")
      ->check(CLI::PositiveNumber);
  app.add_flag("--stats", args->stats, "Print the count of each outcome to stderr");
  return [args]() {
    const std::vector<io::CcdQuery> queries = io::read_ccd_queries(args->queries);
    geometry::CcdOptions options;
    options.min_separation = args->min_separation;
    options.time_tolerance = args->time_tolerance;
    options.max_boxes = args->max_boxes;
    std::map<std::string, long long> outcomes;
    for (const io::CcdQuery& q : queries) {
      const geometry::CcdResult r = geometry::ccd(q.pair, q.start, q.end, options);
      if (r.hit) {
        std::printf("1 %.17g\n", r.toi);
      } else {
        std::printf("0\n");
      }
      ++outcomes[std::string(geometry::to_string(r.outcome))];
    }
    if (args->stats) {
      std::fflush(stdout);
      for (const auto& [name, n] : outcomes) std::fprintf(stderr, "%s %lld\n", name.c_str(), n);
    }
    return 0;
  };
}

}  // namespace crumple::cli
