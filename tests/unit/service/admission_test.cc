#include "fusion/service/admission.h"

#include <gtest/gtest.h>

#include <atomic>
#include <memory>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>


namespace fusion::service {
namespace {

using std::chrono::milliseconds;

TEST(AdmissionTest, SlotsAreHeldUntilDestroyedAndNeverOverTheLimit) {
  std::atomic<std::uint32_t> count{0};
  auto a = CountedSlot::Take(&count, 2);
  auto b = CountedSlot::Take(&count, 2);
  ASSERT_TRUE(a && b);
  EXPECT_FALSE(CountedSlot::Take(&count, 2));
  EXPECT_EQ(count, 2u);
  {
    CountedSlot moved = std::move(*a);
    a.reset();
    EXPECT_EQ(count, 2u) << "a moved-from slot releases nothing";
  }
  EXPECT_EQ(count, 1u);
  EXPECT_TRUE(CountedSlot::Take(&count, 2));  // taken and released at once
  b.reset();
  EXPECT_EQ(count, 0u);
}

Cloud CloudOf(const std::string& id) {
  Cloud c;
  c.sensor_id = id;
  return c;
}

TEST(AdmissionTest, IngestIsBehindForAWindowAfterACloudIsDropped) {
  IngestQueues queues({{"a", 1}});
  queues.Push(CloudOf("a"));
  queues.Push(CloudOf("a"));  // drops one before anyone watched: the baseline
  IngestPressure pressure;
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_FALSE(pressure.Behind(queues, t0));
  queues.Push(CloudOf("a"));  // a drop
  EXPECT_FALSE(pressure.Behind(queues, t0 + milliseconds(50))) << "read at most every 100 ms";
  EXPECT_TRUE(pressure.Behind(queues, t0 + milliseconds(100)));
  EXPECT_TRUE(pressure.Behind(queues, t0 + milliseconds(1050)));
  EXPECT_FALSE(pressure.Behind(queues, t0 + milliseconds(1100))) << "no drop for 1 s";
}

int NiceOfThisThread() {
  return getpriority(PRIO_PROCESS, static_cast<id_t>(::syscall(SYS_gettid)));
}

TEST(AdmissionTest, ThePoolRunsEveryTaskOnItsOwnLowPriorityThreads) {
  const int base = NiceOfThisThread();
  std::atomic<int> ran{0};
  std::atomic<int> wrong_nice{0};
  {
    QueryPool pool(2, base + 7);
    for (int i = 0; i < 50; ++i) {
      pool.Post([&] {
        if (NiceOfThisThread() != std::min(base + 7, 19)) ++wrong_nice;
        ++ran;
      });
    }
  }  // the destructor runs what is queued, then joins
  EXPECT_EQ(ran, 50);
  EXPECT_EQ(wrong_nice, 0);
  EXPECT_EQ(NiceOfThisThread(), base) << "only the pool's threads";
}

TEST(AdmissionTest, ThePoolsThreadsAskForTheShortestSliceWhereTheKernelHasSlices) {
  const std::uint64_t own_slice_ns = ThisThreadSliceNs();
  if (own_slice_ns == 0) GTEST_SKIP() << "this kernel has no per-thread time slice (< 6.12)";
  std::atomic<std::uint64_t> pool_slice_ns{0};
  {
    QueryPool pool(1, NiceOfThisThread() + 1);
    pool.Post([&] { pool_slice_ns = ThisThreadSliceNs(); });
  }
  EXPECT_EQ(pool_slice_ns, 100'000u) << "0.1 ms: a waking query thread preempts at once";
  EXPECT_EQ(ThisThreadSliceNs(), own_slice_ns) << "only the pool's threads";
}

TEST(AdmissionTest, ThePoolCallsItsAfterTaskHookAfterEachTaskOnceItsCapturesAreGone) {
  std::atomic<int> hooks{0};
  std::atomic<int> captures_alive_at_hook{0};
  auto capture = std::make_shared<int>(0);
  const std::weak_ptr<int> watch = capture;
  {
    QueryPool pool(1, NiceOfThisThread(), [&] {
      ++hooks;
      if (!watch.expired()) ++captures_alive_at_hook;
    });
    pool.Post([held = std::move(capture)] { (void)held; });
    for (int i = 0; i < 19; ++i) pool.Post([] {});
  }  // the destructor runs what is queued, then joins
  EXPECT_EQ(hooks, 20);
  EXPECT_EQ(captures_alive_at_hook, 0) << "a task's captures were still alive when the hook ran";
}

TEST(AdmissionTest, TheHeapTrimmerTrimsAtMostOncePerInterval) {
  HeapTrimmer trimmer(std::chrono::milliseconds(500));
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_TRUE(trimmer.MaybeTrim(t0)) << "the first call trims";
  EXPECT_FALSE(trimmer.MaybeTrim(t0 + std::chrono::milliseconds(499)));
  EXPECT_TRUE(trimmer.MaybeTrim(t0 + std::chrono::milliseconds(500)));
  EXPECT_FALSE(trimmer.MaybeTrim(t0 + std::chrono::milliseconds(600)));
}

}  // namespace
}  // namespace fusion::service
