#include "fusion/service/admission.h"

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <thread>

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

TEST(AdmissionTest, QueryThreadsRunAtTheirNiceValueOnce) {
  int first = 0, second = 0, other = 0;
  const int base = NiceOfThisThread();
  std::thread query([&] {
    LowerThreadPriorityOnce(base + 5);
    first = NiceOfThisThread();
    LowerThreadPriorityOnce(base + 9);  // once per thread: no further change
    second = NiceOfThisThread();
  });
  query.join();
  std::thread([&] { other = NiceOfThisThread(); }).join();
  EXPECT_EQ(first, std::min(base + 5, 19));
  EXPECT_EQ(second, first);
  EXPECT_EQ(other, base) << "only the calling thread";
  EXPECT_EQ(NiceOfThisThread(), base);
}

}  // namespace
}  // namespace fusion::service
