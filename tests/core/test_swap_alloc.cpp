// The host memory of the swap plan (swap.hpp: plan_swap_into): a plan made
// again for as many PEs and the same image size takes no fresh memory (the
// engine plans every frame), and one whose rectangles go to held_out keeps
// none of them. Counted with this executable's own operator new (a test
// file of its own, so that no other test pays the count).
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>

#include "simdvol/match.hpp"
#include "simdvol/swap.hpp"
#include "simdvol/view.hpp"

namespace {
std::atomic<bool> g_counting{false};
std::atomic<long> g_allocations{0};
}  // namespace

// (delete replaced too, with free: new's malloc and free pair up, also
// under the sanitizers; GCC cannot see that the two belong together)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t bytes) {
  if (g_counting.load(std::memory_order_relaxed)) ++g_allocations;
  if (void* p = std::malloc(bytes == 0 ? 1 : bytes)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept {
  std::free(p);
}
void operator delete(void* p, std::size_t) noexcept {
  std::free(p);
}
#pragma GCC diagnostic pop

using namespace simdvol;

namespace {

// The allocations (operator new) that `f` makes.
template <class F>
long allocations(F&& f) {
  g_allocations = 0;
  g_counting = true;
  f();
  g_counting = false;
  return g_allocations.load();
}

bool same_schedule(const SwapPlan& a, const SwapPlan& b) {
  return a.layout == b.layout && a.width == b.width && a.height == b.height && a.pes == b.pes &&
         a.bits == b.bits && a.front == b.front && a.offset == b.offset && a.xpe == b.xpe &&
         a.ype == b.ype;
}

}  // namespace

// Before: every plan_swap_into allocated its group boxes (32 bytes a PE),
// two residue tables (4 bytes a PE each), the counts (8 bytes a PE) and
// the pixel bits: 5 allocations a frame, 48 bytes a PE (48 MB at 2^20 PEs,
// fresh pages every frame).
TEST(SwapPlanMemory, PlanMadeAgainTakesNoFreshMemory) {
  const Dims3 d{64, 48, 40};
  for (int64_t P : {int64_t(1), int64_t(8), int64_t(512), int64_t(4096)})
    for (SwapLayout L : {SwapLayout::cut_and_stack, SwapLayout::hierarchical}) {
      SCOPED_TRACE("P " + std::to_string(P) + " " + swap_layout_name(L));
      const KdSplit split = kd_split(d, P);
      const PeGrid grid = pe_grid(P);
      const ViewGeometry a = make_view(d, {1, 1, 1}, {20, 35, 10}, 96, 96, Sampling::voxel);
      const ViewGeometry b = make_view(d, {1, 1, 1}, {-23.5, 71.25, 133}, 96, 96, Sampling::voxel);
      ASSERT_EQ(a.width(), b.width());
      ASSERT_EQ(a.height(), b.height());
      const Matching ma = match_reference(a, split), mb = match_reference(b, split);
      SwapPlan kept;
      plan_swap_into(kept, ma.rects, split, a, grid, L);  // the first: its storage
      EXPECT_EQ(allocations([&] { plan_swap_into(kept, mb.rects, split, b, grid, L); }), 0);
      EXPECT_TRUE(same_schedule(kept, plan_swap(mb.rects, split, b, grid, L)));
      EXPECT_EQ(allocations([&] { plan_swap_into(kept, ma.rects, split, a, grid, L); }), 0);
      const SwapPlan want = plan_swap(ma.rects, split, a, grid, L);
      EXPECT_TRUE(same_schedule(kept, want));
      EXPECT_EQ(kept.held, want.held);
      // The rectangles to held_out (the engine's mapped tables): none kept
      // on the host, no allocation.
      const int N = split.bits;
      std::vector<std::vector<SwapRect>> out(static_cast<std::size_t>(N + 1),
                                             std::vector<SwapRect>(static_cast<std::size_t>(P)));
      std::vector<SwapRect*> ptr;
      for (auto& o : out) ptr.push_back(o.data());
      EXPECT_EQ(allocations([&] { plan_swap_into(kept, ma.rects, split, a, grid, L, ptr.data()); }),
                0);
      std::size_t held_capacity = 0;
      for (const auto& h : kept.held) held_capacity += h.capacity();
      EXPECT_EQ(held_capacity, 0u);  // (before: (N + 1) x P rectangles kept)
      EXPECT_EQ(out, want.held);
      EXPECT_TRUE(same_schedule(kept, want));
    }
}
