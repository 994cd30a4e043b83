// The detectors on the host application's threads (`set_task_dispatcher`): the same contacts
// as on crumple's own team, with the work run as the host's tasks.
#include <crumple/core/parallel.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/mesh/shapes.hpp>
#include <support/host_pool.hpp>
#include <support/meshes.hpp>

#include <gtest/gtest.h>

#include <sstream>
#include <string>

namespace crumple {
namespace {

std::string text(const ContactSet& set) {
  std::ostringstream out;
  write_contacts(out, set);
  return out.str();
}

TEST(HostDispatch, DetectorsGiveTheTeamsContacts) {
  const TriMesh mesh = shapes::lattice(16, 16);
  const Positions x0 = testing::crumple_lattice(mesh, 0.2, 21);
  const Positions x1 = testing::jitter(x0, 0.004, 22);
  DetectorOptions options;
  options.thickness = 0.03;
  options.kinds = ContactKinds::parse("vf,ee,tt");
  options.threads = 0;
  for (const std::string spec : {"naive", "kdop", "hash", "sap"}) {
    ContactSet team0, team1, host0, host1;
    {
      auto d = make_detector(MethodSpec::parse(spec), options);
      d->set_topology(mesh.topology_ptr());
      d->update(x0, team0);
      d->update(x0, x1, team1);
    }
    testing::HostPool pool(2);
    {
      const testing::DispatcherScope scope(pool.dispatcher());
      auto d = make_detector(MethodSpec::parse(spec), options);
      d->set_topology(mesh.topology_ptr());
      d->update(x0, host0);
      d->update(x0, x1, host1);
    }
    EXPECT_GT(team0.size(), 50u) << spec;
    EXPECT_EQ(text(host0), text(team0)) << spec;
    EXPECT_EQ(text(host1), text(team1)) << spec;
    EXPECT_GT(pool.tasks(), 0u) << spec;  // the work went through the host
  }
}

}  // namespace
}  // namespace crumple
