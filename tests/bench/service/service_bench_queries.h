// service_bench (service_bench.cc): the small queries timed while sensors stream (QueryPoints
// of 1 and 10 points, CastRay), their latency rows, and the table of per-sensor cloud counters.
#pragma once

#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <random>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "fusion/v1/map_service.grpc.pb.h"
#include "service_bench_common.h"
#include "service_bench_fusiond.h"

namespace fusion::service_bench {

struct CounterDelta {
  std::uint64_t received = 0, dropped = 0, rejected = 0, integrated = 0;
};

inline CounterDelta Delta(const v1::SensorCounters& a, const v1::SensorCounters& b) {
  return {b.received() - a.received(), b.dropped() - a.dropped(), b.rejected() - a.rejected(),
          b.integrated() - a.integrated()};
}

inline void PrintCounterTable(const std::vector<std::pair<std::string, double>>& rates,
                              const std::map<std::string, StreamStats>& published,
                              const std::map<std::string, v1::SensorCounters>& before,
                              const std::map<std::string, v1::SensorCounters>& after) {
  std::printf(
      "| sensor | rate | published | received | DDS lost (published-received) | "
      "dropped (queue) | rejected | integrated | not integrated (published-integrated) "
      "|\n|---|---|---|---|---|---|---|---|---|\n");
  for (const auto& [id, hz] : rates) {
    const auto& pub = published.at(id);
    const CounterDelta d = Delta(before.at(id), after.at(id));
    std::printf(
        "| %s | %.0f Hz | %llu | %llu | %lld | %llu | %llu | %llu | %lld |\n", id.c_str(), hz,
        static_cast<unsigned long long>(pub.written), static_cast<unsigned long long>(d.received),
        static_cast<long long>(pub.written) - static_cast<long long>(d.received),
        static_cast<unsigned long long>(d.dropped), static_cast<unsigned long long>(d.rejected),
        static_cast<unsigned long long>(d.integrated),
        static_cast<long long>(pub.written) - static_cast<long long>(d.integrated));
    if (pub.write_failures > 0 || pub.late_ticks > 0) {
      std::printf(
          "|   (%s publisher: %llu dds_write failures, %llu late ticks, max write %.1f "
          "ms) |||||||||\n",
          id.c_str(), static_cast<unsigned long long>(pub.write_failures),
          static_cast<unsigned long long>(pub.late_ticks), pub.max_write_ms);
    }
  }
}

// A kind of small query for the latency loops: its name and one call.
struct SmallQuery {
  std::string name;
  std::function<grpc::Status(grpc::ClientContext*)> call;
};

inline SmallQuery OnePointQuery(v1::FusionMap::Stub& stub) {
  v1::QueryPointsRequest request;
  *request.add_points() = P(kOnBoard);
  return {"QueryPoints, 1 point", [&stub, request](grpc::ClientContext* context) {
            v1::QueryPointsResponse reply;
            return stub.QueryPoints(context, request, &reply);
          }};
}

// Board-area points: some occupied, some free, some unknown.
inline SmallQuery TenPointsQuery(v1::FusionMap::Stub& stub) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> ux(0.3, 2.2), uy(-1.0, 1.0), uz(-0.45, 0.75);
  v1::QueryPointsRequest request;
  for (int i = 0; i < 10; ++i) *request.add_points() = P({ux(rng), uy(rng), uz(rng)});
  return {"QueryPoints, 10 points", [&stub, request](grpc::ClientContext* context) {
            v1::QueryPointsResponse reply;
            return stub.QueryPoints(context, request, &reply);
          }};
}

// Counts its hits in *hits (read it after the loop that issues the queries).
inline SmallQuery CastRayQuery(v1::FusionMap::Stub& stub, int* hits) {
  v1::CastRayRequest request;
  *request.mutable_origin() = P({0, 0, 0});
  *request.mutable_direction() = P({1, 0.05, 0.1});
  request.set_max_range_m(5);
  request.set_ignore_unknown(true);
  return {"CastRay (through unknown, 5 m)", [&stub, request, hits](grpc::ClientContext* context) {
            v1::CastRayResponse reply;
            const grpc::Status status = stub.CastRay(context, request, &reply);
            *hits += reply.hit() ? 1 : 0;
            return status;
          }};
}

// Issues the queries in rotation, one every 2 ms, while keep_going() holds; returns the latency
// (ms) of each successful call, per kind, and counts the failed calls in *errors.
inline std::vector<std::vector<double>> RunSmallQueries(const std::vector<SmallQuery>& queries,
                                                        const std::function<bool()>& keep_going,
                                                        int* errors) {
  std::vector<std::vector<double>> latency_ms(queries.size());
  auto next = Clock::now();
  for (std::size_t i = 0; keep_going(); ++i) {
    const std::size_t kind = i % queries.size();
    grpc::ClientContext context;
    context.set_deadline(In(1000ms));
    const auto t0 = Clock::now();
    const grpc::Status status = queries[kind].call(&context);
    const double ms = Ms(Clock::now() - t0);
    if (status.ok())
      latency_ms[kind].push_back(ms);
    else
      ++*errors;
    next += 2ms;
    std::this_thread::sleep_until(next);
  }
  return latency_ms;
}

inline std::vector<std::string> NamesOf(const std::vector<SmallQuery>& queries) {
  std::vector<std::string> names;
  for (const auto& query : queries) names.push_back(query.name);
  return names;
}

// One table row per query kind and one for all of them: samples, p50, p99, max (ms).
inline void PrintQueryRows(const char* label, const std::vector<std::string>& names,
                           const std::vector<std::vector<double>>& latency_ms) {
  const auto row = [label](const std::string& name, const std::vector<double>& v) {
    std::printf("| %s | %s | %zu | %.3f | %.3f | %.2f |\n", label, name.c_str(), v.size(),
                Percentile(v, 0.5), Percentile(v, 0.99),
                v.empty() ? NAN : *std::max_element(v.begin(), v.end()));
  };
  std::vector<double> combined;
  for (std::size_t k = 0; k < names.size(); ++k) {
    row(names[k], latency_ms[k]);
    combined.insert(combined.end(), latency_ms[k].begin(), latency_ms[k].end());
  }
  row("all small queries", combined);
}

}  // namespace fusion::service_bench
