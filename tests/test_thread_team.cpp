// The cpu backend's persistent thread team (cpu/thread_team.hpp) and its
// region slices (cpu/partition.hpp): every member runs the job, a barrier
// orders every member's writes before any member's next reads, its `last`
// runs exactly once per barrier, a throw in it reaches the caller, idle
// members that went to sleep wake for the next job, and the slices cover the
// region's lists exactly once. scripts/tsan runs this file under
// ThreadSanitizer (the team is our code, so TSan sees its synchronisation).
#include <gtest/gtest.h>
#include <sched.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <chrono>
#include <numeric>
#include <stdexcept>
#include <thread>
#include <vector>

#include "core/region.hpp"
#include "cpu/host_backend.hpp"
#include "cpu/partition.hpp"
#include "cpu/thread_team.hpp"
#include "tests/backend_test_support.hpp"

namespace tissue::cpu {
namespace {

TEST(ThreadTeam, RejectsSizesOutsideItsRange) {
  EXPECT_THROW(ThreadTeam(0), std::invalid_argument);
  EXPECT_THROW(ThreadTeam(ThreadTeam::kMaxSize + 1), std::invalid_argument);
  ThreadTeam team(2);
  EXPECT_THROW(team.run(3, [](int) {}), std::invalid_argument);
  EXPECT_THROW(team.run(0, [](int) {}), std::invalid_argument);
}

// Each round, every member writes its slot; after the barrier every member
// must see every slot of that round (a barrier that released early, or a
// `last` that ran on a stale view, fails the sums).
void rounds_see_each_others_writes(int size, int active, int rounds) {
  ThreadTeam team(size);
  std::vector<long> slot(std::size_t(active), 0);
  std::vector<long> seen(std::size_t(active), 0);
  long last_runs = 0, last_sum_errors = 0;
  team.run(active, [&](int r) {
    for (int k = 1; k <= rounds; ++k) {
      slot[r] = long(k) * (r + 1);
      team.barrier([&] {
        ++last_runs;
        const long expect = long(k) * active * (active + 1) / 2;
        if (std::accumulate(slot.begin(), slot.end(), 0L) != expect) ++last_sum_errors;
      });
      seen[r] += std::accumulate(slot.begin(), slot.end(), 0L);
      team.barrier();  // nobody writes round k + 1 before everyone has read round k
    }
  });
  EXPECT_EQ(last_runs, rounds);
  EXPECT_EQ(last_sum_errors, 0);
  const long per_member = long(active) * (active + 1) / 2 * long(rounds) * (rounds + 1) / 2;
  for (int r = 0; r < active; ++r) EXPECT_EQ(seen[r], per_member) << "member " << r;
}

TEST(ThreadTeam, BarrierOrdersEveryMembersWrites) {
  rounds_see_each_others_writes(1, 1, 100);
  rounds_see_each_others_writes(2, 2, 2000);
  rounds_see_each_others_writes(4, 4, 500);
  rounds_see_each_others_writes(6, 3, 500);  // a job on part of the team
  rounds_see_each_others_writes(9, 9, 50);   // more members than this machine may have cores
}

TEST(ThreadTeam, EveryActiveMemberRunsEachJobOnce) {
  ThreadTeam team(5);
  for (int job = 0; job < 300; ++job) {
    const int active = 1 + job % 5;
    std::vector<std::atomic<int>> ran(5);
    team.run(active, [&](int r) { ran[r].fetch_add(1); });
    for (int r = 0; r < 5; ++r) ASSERT_EQ(ran[r].load(), r < active ? 1 : 0) << "job " << job << " member " << r;
  }
}

TEST(ThreadTeam, SleepingMembersWakeForTheNextJob) {
  ThreadTeam team(3);
  for (int job = 0; job < 5; ++job) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));  // far past the idle spin: the members sleep
    std::atomic<int> ran{0};
    team.run(3, [&](int) {
      ran.fetch_add(1);
      team.barrier();
    });
    EXPECT_EQ(ran.load(), 3);
  }
}

TEST(ThreadTeam, AThrowInABarriersLastReachesTheCallerAndTheTeamCarriesOn) {
  ThreadTeam team(3);
  std::atomic<int> after{0};
  EXPECT_THROW(team.run(3,
                        [&](int) {
                          for (int k = 0; k < 10; ++k) {
                            if (!team.barrier([&] {
                                  if (k == 4) throw std::runtime_error("contact stage failed");
                                }))
                              return;
                            after.fetch_add(1);
                          }
                        }),
               std::runtime_error);
  EXPECT_EQ(after.load(), 3 * 4);  // rounds 0..3 completed by all three, nobody went on past round 4
  std::atomic<int> ran{0};
  team.run(3, [&](int) { ran.fetch_add(1); });
  EXPECT_EQ(ran.load(), 3);
}

TEST(RegionSlices, CoverTheRegionOnceWithLaneAlignedElementCuts) {
  const auto m = test::box_model(6, true);
  for (int depth : {kDepthAll, 1, 3}) {
    const index_t seed = m.n_nodes / 2;
    const Region region = flood_fill(m, std::span<const index_t>(&seed, depth == kDepthAll ? 0 : 1), depth);
    for (int parts : {1, 2, 3, 7, 16}) {
      Slices s;
      slice_region(region, m.node_elem_start.data(), parts, 16, s);
      ASSERT_EQ(s.parts, parts);
      EXPECT_EQ(s.elem_cut.front(), 0u);
      EXPECT_EQ(s.elem_cut.back(), region.elems.size());
      EXPECT_EQ(s.node_cut.front(), 0u);
      EXPECT_EQ(s.node_cut.back(), region.nodes.size());
      std::size_t elems = 0, nodes = 0;
      for (int r = 0; r < parts; ++r) {
        ASSERT_LE(s.elem_cut[r], s.elem_cut[r + 1]);
        ASSERT_LE(s.node_cut[r], s.node_cut[r + 1]);
        if (s.elem_cut[r + 1] != region.elems.size()) {
          EXPECT_EQ(s.elem_cut[r + 1] % 16, 0u) << "cut " << r + 1;
        }
        elems += s.elems(region.elems, r).size();
        nodes += s.nodes(region.nodes, r).size();
      }
      EXPECT_EQ(elems, region.elems.size());
      EXPECT_EQ(nodes, region.nodes.size());
      if (parts == 2 && region.nodes.size() > 100) {  // node shares balance their list lengths
        const auto cost = [&](std::size_t b, std::size_t e) {
          std::size_t c = 0;
          for (std::size_t k = b; k < e; ++k) c += 1 + m.node_elem_start[region.nodes[k] + 1] - m.node_elem_start[region.nodes[k]];
          return double(c);
        };
        const double c0 = cost(0, s.node_cut[1]), c1 = cost(s.node_cut[1], s.node_cut[2]);
        EXPECT_NEAR(c0 / (c0 + c1), 0.5, 0.02);
      }
    }
  }
}

/// A cpu backend on a team of `members`, uploaded with m.
template <class T>
std::unique_ptr<CpuBackend<T>> team_backend(int members, const TissueModel<double>& m) {
  auto b = std::make_unique<CpuBackend<T>>();
  b->set_team_size(members);
  b->upload(m);
  return b;
}

// The backend's advance and reduce on a team of 4, with TBB held to the
// calling thread (its prebuilt pool is invisible to ThreadSanitizer, so
// under scripts/tsan only the team's threads run): the same bits as one member.
TEST(TeamOnTheCpuBackend, FourMembersGiveOneMembersBits) {
  const tbb::global_control one_tbb_thread(tbb::global_control::max_allowed_parallelism, 1);
  const auto m = test::box_model(8, true);
  const auto run = [&](int members) {
    const auto owner = team_backend<float>(members, m);
    CpuBackend<float>& b = *owner;
    b.set_displacements(test::field(m, [](Vec3<double> X) { return Vec3<double>{0, 0, -0.01 * X.z}; }));
    std::vector<Reductions> red;
    for (int k = 0; k < 5; ++k) {
      b.advance(7);
      red.push_back(b.reduce());
    }
    EXPECT_EQ(b.busy_team_members(), members);
    return std::pair{b.download(), red};
  };
  const auto [f1, r1] = run(1);
  const auto [f4, r4] = run(4);
  EXPECT_EQ(f1.u, f4.u);
  EXPECT_EQ(f1.f, f4.f);
  EXPECT_EQ(f1.node_p, f4.node_p);
  ASSERT_EQ(r1.size(), r4.size());
  for (std::size_t k = 0; k < r1.size(); ++k) {
    EXPECT_EQ(r1[k].kinetic, r4[k].kinetic) << k;
    EXPECT_EQ(r1[k].strain_energy, r4[k].strain_energy) << k;
    EXPECT_EQ(r1[k].free_force2, r4[k].free_force2) << k;
    EXPECT_GT(r1[k].kinetic, 0.0) << k;
  }
}

// The same with a tool pressing into the top: the contact stage runs in the
// barrier's last(), on whichever member arrives last.
TEST(TeamOnTheCpuBackend, TheContactStageGivesTheSameBitsOnAnyMember) {
  const tbb::global_control one_tbb_thread(tbb::global_control::max_allowed_parallelism, 1);
  const auto m = test::box_model(8, true);
  double top = 0;
  for (index_t a = 0; a < m.n_nodes; ++a) top = std::max(top, m.X[2 * std::size_t(m.n_nodes) + a]);
  const auto run = [&](int members) {
    const auto owner = team_backend<double>(members, m);
    CpuBackend<double>& b = *owner;
    const ToolShape tool{"probe", 0.1 * top, 0};
    b.set_tools(std::span<const ToolShape>(&tool, 1));
    std::vector<Reductions> red;
    for (int k = 0; k < 8; ++k) {  // down 2 % of the height per advance, from just above the top
      const auto at = [&](int j) { return ToolPose{{0.5 * top, 0.5 * top, top + tool.radius - 0.02 * top * j}, {0, 0, 1}}; };
      const ToolMotion mv{at(k), at(k + 1)};
      b.move_tools(std::span<const ToolMotion>(&mv, 1));
      b.advance(5);
      red.push_back(b.reduce());
    }
    return std::pair{b.download(), red};
  };
  const auto [f1, r1] = run(1);
  const auto [f4, r4] = run(4);
  EXPECT_EQ(f1.u, f4.u);
  EXPECT_EQ(f1.f, f4.f);
  ASSERT_EQ(r1.size(), r4.size());
  for (std::size_t k = 0; k < r1.size(); ++k) {
    EXPECT_EQ(r1[k].tools[0].contact, r4[k].tools[0].contact) << k;
    EXPECT_EQ(r1[k].tools[0].reaction.z, r4[k].tools[0].reaction.z) << k;
    EXPECT_EQ(r1[k].kinetic, r4[k].kinetic) << k;
  }
  EXPECT_GT(r1.back().tools[0].contact, 0);  // the tool did press
  EXPECT_GT(std::fabs(r1.back().tools[0].reaction.z), 0.0);
}

// A new region after steps on the whole mesh, with as many busy members as
// before: the slices are cut again (stale cuts would run past the region's lists).
TEST(TeamOnTheCpuBackend, ANewRegionIsSlicedAgain) {
  const tbb::global_control one_tbb_thread(tbb::global_control::max_allowed_parallelism, 1);
  const auto m = test::box_model(10, true);
  const auto run = [&](int members) {
    const auto owner = team_backend<float>(members, m);
    CpuBackend<float>& b = *owner;
    b.set_displacements(test::field(m, [](Vec3<double> X) { return Vec3<double>{0.01 * X.z, 0, 0}; }));
    b.advance(5);
    const int whole = b.busy_team_members();
    const index_t seed = m.n_nodes - 1;
    const RegionSizes r = b.build_region(std::span<const index_t>(&seed, 1), 6);
    EXPECT_LT(r.n_elems, m.n_elems);
    b.advance(5);
    EXPECT_EQ(b.busy_team_members(), whole) << "the test wants the same member count for both regions";
    return b.download();
  };
  const Fields one = run(1), four = run(4);
  EXPECT_EQ(one.u, four.u);
  EXPECT_EQ(one.f, four.f);
}

TEST(ThreadTeam, DefaultSizeFollowsTbbsLimits) {
  {
    const tbb::global_control two(tbb::global_control::max_allowed_parallelism, 2);
    EXPECT_LE(default_team_size(), 2);
    EXPECT_GE(default_team_size(), 1);
  }
  tbb::task_arena one(1);
  one.execute([] { EXPECT_EQ(default_team_size(), 1); });
}

TEST(ThreadTeam, DefaultSizeFollowsTheAffinityMaskNarrowedLater) {
  cpu_set_t all;
  ASSERT_EQ(::sched_getaffinity(0, sizeof all, &all), 0);
  int first = -1;
  for (int c = 0; c < CPU_SETSIZE && first < 0; ++c)
    if (CPU_ISSET(c, &all)) first = c;
  std::thread([first] {  // a thread kept to one core after TBB read the process's mask: a team of one
    cpu_set_t one;
    CPU_ZERO(&one);
    CPU_SET(first, &one);
    ASSERT_EQ(::sched_setaffinity(0, sizeof one, &one), 0);
    EXPECT_EQ(default_team_size(), 1);
  }).join();
}

TEST(ThreadTeam, TheThreadCapIsAWholeNumberOrUnset) {
  EXPECT_EQ(thread_cap(nullptr), 0);
  EXPECT_EQ(thread_cap(""), 0);
  EXPECT_EQ(thread_cap("3"), 3);
  for (const char* bad : {"0", "-2", "abc", "2.5", "1000"}) {
    try {
      thread_cap(bad);
      ADD_FAILURE() << bad;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(std::string("TISSUE_THREADS='") + bad + "' must be a whole number in 1..255"),
                std::string::npos)
          << e.what();
    }
  }
}

TEST(ThreadTeam, RunInsideAJobIsRefused) {
  ThreadTeam team(2);
  std::atomic<int> refused{0};
  team.run(1, [&](int) {
    try {
      team.run(1, [](int) {});
    } catch (const std::logic_error&) {
      refused.fetch_add(1);
    }
  });
  EXPECT_EQ(refused.load(), 1);
}

TEST(RegionSlices, SmallRegionsKeepFewerMembersBusy) {
  EXPECT_EQ(busy_members(10, 16), 1);
  EXPECT_EQ(busy_members(kMinMemberElems * 3, 16), 3);
  EXPECT_EQ(busy_members(8576, 16), 16);
  EXPECT_EQ(busy_members(8576, 2), 2);
  EXPECT_EQ(busy_members(0, 4), 1);
}

}  // namespace
}  // namespace tissue::cpu
