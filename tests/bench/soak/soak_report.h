// soak: the results of a run, their tables (Markdown, for BENCHMARKS.md) and JSON.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "fusion/v1/map_service.pb.h"
#include "soak_fusiond.h"
#include "soak_recorder.h"

namespace fusion::soak {

struct RssSample {
  double t_s = 0, rss_mb = 0;
};

struct SensorResult {
  std::string id;
  std::size_t points_per_frame = 0;
  std::uint64_t published = 0, write_failures = 0, late_ticks = 0;
  fusion::v1::SensorCounters before, after;
  [[nodiscard]] std::uint64_t Delta(std::uint64_t (fusion::v1::SensorCounters::*field)()
                                        const) const {
    return (after.*field)() - (before.*field)();
  }
  [[nodiscard]] std::uint64_t lost() const {  // published, never integrated
    const auto integrated = Delta(&fusion::v1::SensorCounters::integrated);
    return published > integrated ? published - integrated : 0;
  }
};

struct StreamCounts {
  std::uint64_t sessions = 0, messages = 0, voxels = 0, full_messages = 0, silent_sessions = 0;
};

struct RunResult {
  std::string command_line, date, fusiond_command, address, run_dir;
  unsigned domain = 0;
  double load_s = 0;                                 // the load ran this long
  double fusiond_cpu_s = -1, soak_cpu_s = -1;        // CPU time over the load (-1: not known)
  std::string load_average_start, load_average_end;  // /proc/loadavg
  std::array<RpcRecord, kRpcCount> records;
  StreamCounts streams;
  std::vector<SensorResult> sensors;
  fusion::v1::Stats stats_after;
  std::vector<RssSample> rss;
  bool own_fusiond = true, fusiond_died = false;
  int fusiond_exit_code = 0;
  std::uint64_t monitor_failures = 0;
  LogSummary log;
};

// ---- derived figures --------------------------------------------------------------------------

struct RssVerdict {
  bool known = false;  // a sample at 60 s and one after it
  double at_60s_mb = 0, max_after_mb = 0, growth_mb = 0, growth_pct = 0, slope_mb_per_min = 0;
  double first_third_mb = 0, last_third_mb = 0;  // means of the samples after 60 s
  // The level RSS returns to: the median of each whole minute after the first. Single samples
  // jump by tens of MB while heavy queries (GetSnapshot, FindPlanes) hold their buffers, so the
  // verdict compares levels, not the peak against one sample.
  std::vector<double> minute_medians_mb;  // minute 2, 3, ... (60-120 s, 120-180 s, ...)
  double level_growth_pct = 0;            // highest later minute median vs minute 2's
  bool flat = false;                      // level_growth_pct <= 10
};

inline double MedianOf(std::vector<double> values) {
  if (values.empty()) return 0;
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  return n % 2 == 1 ? values[n / 2] : (values[n / 2 - 1] + values[n / 2]) / 2;
}

// Medians of the samples in [60 k, 60 (k + 1)) s for k >= 1; a minute with fewer than 3 samples
// (the run's tail) is left out.
inline std::vector<double> MinuteMedians(const std::vector<RssSample>& rss) {
  std::vector<double> medians;
  for (int minute = 1;; ++minute) {
    std::vector<double> in;
    bool later = false;
    for (const auto& s : rss) {
      if (s.t_s >= 60.0 * (minute + 1) - 0.5) later = true;
      if (s.t_s >= 60.0 * minute - 0.5 && s.t_s < 60.0 * (minute + 1) - 0.5) in.push_back(s.rss_mb);
    }
    if (in.size() >= 3) medians.push_back(MedianOf(in));
    if (!later) return medians;
  }
}

// Least-squares slope of the samples after 60 s, in MB per minute.
inline double SlopeMbPerMin(const std::vector<RssSample>& after) {
  if (after.size() < 2) return 0;
  double st = 0, sr = 0, stt = 0, str = 0;
  for (const auto& s : after) {
    st += s.t_s, sr += s.rss_mb, stt += s.t_s * s.t_s, str += s.t_s * s.rss_mb;
  }
  const double n = static_cast<double>(after.size());
  const double denominator = n * stt - st * st;
  return denominator > 0 ? 60 * (n * str - st * sr) / denominator : 0;
}

inline RssVerdict JudgeRss(const std::vector<RssSample>& rss) {
  RssVerdict v;
  const auto at = std::find_if(rss.begin(), rss.end(), [](const auto& s) { return s.t_s >= 59.5; });
  if (at == rss.end() || at + 1 == rss.end()) return v;
  const std::vector<RssSample> after(at + 1, rss.end());
  v.known = true;
  v.at_60s_mb = at->rss_mb;
  for (const auto& s : after) v.max_after_mb = std::max(v.max_after_mb, s.rss_mb);
  v.growth_mb = v.max_after_mb - v.at_60s_mb;
  v.growth_pct = 100 * v.growth_mb / v.at_60s_mb;
  v.slope_mb_per_min = SlopeMbPerMin(after);
  const std::size_t third = std::max<std::size_t>(1, after.size() / 3);
  for (std::size_t i = 0; i < third; ++i) {
    v.first_third_mb += after[i].rss_mb / static_cast<double>(third);
    v.last_third_mb += after[after.size() - 1 - i].rss_mb / static_cast<double>(third);
  }
  v.minute_medians_mb = MinuteMedians(rss);
  if (v.minute_medians_mb.size() < 2) {
    v.known = false;  // one level only: nothing to compare
    return v;
  }
  const double level_max =
      *std::max_element(v.minute_medians_mb.begin() + 1, v.minute_medians_mb.end());
  v.level_growth_pct = 100 * (level_max - v.minute_medians_mb.front()) / v.minute_medians_mb.front();
  v.flat = v.level_growth_pct <= 10;
  return v;
}

struct CloudTotals {
  std::uint64_t published = 0, lost = 0, dropped = 0, rejected = 0;
  [[nodiscard]] double lost_pct() const {
    return published > 0 ? 100.0 * static_cast<double>(lost) / static_cast<double>(published) : 0;
  }
};

inline CloudTotals SumClouds(const std::vector<SensorResult>& sensors) {
  CloudTotals t;
  for (const auto& s : sensors) {
    t.published += s.published;
    t.lost += s.lost();
    t.dropped += s.Delta(&fusion::v1::SensorCounters::dropped);
    t.rejected += s.Delta(&fusion::v1::SensorCounters::rejected);
  }
  return t;
}

inline std::uint64_t NonShedErrors(const RunResult& r) {
  std::uint64_t n = 0;
  for (const auto& rec : r.records) n += rec.Count(ErrorCode);
  return n;
}

// The reasons the run failed; empty: passed.
inline std::vector<std::string> Failures(const RunResult& r) {
  std::vector<std::string> why;
  const CloudTotals clouds = SumClouds(r.sensors);
  if (const auto n = NonShedErrors(r); n > 0)
    why.push_back(std::to_string(n) + " errors (not shed)");
  if (clouds.lost_pct() > 1.0) {
    char text[96];
    std::snprintf(text, sizeof text, "%.2f %% of the clouds not integrated (> 1 %%)",
                  clouds.lost_pct());
    why.emplace_back(text);
  }
  if (clouds.rejected > 0) why.push_back(std::to_string(clouds.rejected) + " clouds rejected");
  if (r.fusiond_died) why.emplace_back("fusiond exited during the run");
  if (r.own_fusiond && r.fusiond_exit_code != 0)
    why.push_back("fusiond exit code " + std::to_string(r.fusiond_exit_code));
  if (r.monitor_failures > 0)
    why.push_back(std::to_string(r.monitor_failures) + " failed GetStats/ListSensors polls");
  return why;
}

// ---- tables -----------------------------------------------------------------------------------

inline void PrintRpcTable(const RunResult& r) {
  std::printf(
      "### Calls per RPC (latency of the OK calls; StreamUpdates: one call per session, "
      "latency = time to its first message)\n\n"
      "| RPC | calls | OK | shed | errors | p50 ms | p99 ms | max ms |\n"
      "|---|---|---|---|---|---|---|---|\n");
  for (std::size_t i = 0; i < kRpcCount; ++i) {
    const RpcRecord& rec = r.records[i];
    const auto& v = rec.latency_ms;
    std::printf("| %s | %llu | %llu | %llu | %llu | %.2f | %.2f | %.1f |\n",
                RpcName(static_cast<Rpc>(i)), static_cast<unsigned long long>(rec.Count(AnyCode)),
                static_cast<unsigned long long>(rec.Count(OkCode)),
                static_cast<unsigned long long>(rec.Count(ShedCode)),
                static_cast<unsigned long long>(rec.Count(ErrorCode)), Percentile(v, 0.5),
                Percentile(v, 0.99), v.empty() ? NAN : *std::max_element(v.begin(), v.end()));
  }
  std::printf("\n");
}

inline void PrintErrors(const RunResult& r) {
  std::printf("### Calls that were not OK, by RPC and status code\n\n");
  bool any = false;
  for (std::size_t i = 0; i < kRpcCount; ++i) {
    for (const auto& [code, count] : r.records[i].calls_by_code) {
      if (code == 0) continue;
      if (!any)
        std::printf("| RPC | code | calls | kind | first messages |\n|---|---|---|---|---|\n");
      any = true;
      std::string messages;
      for (const auto& m : r.records[i].first_messages.at(code))
        messages += (messages.empty() ? "" : " / ") + m;
      std::printf("| %s | %s | %llu | %s | %s |\n", RpcName(static_cast<Rpc>(i)),
                  CodeName(code).c_str(), static_cast<unsigned long long>(count),
                  IsShed(code) ? "shed" : "error", messages.c_str());
    }
  }
  std::printf(any ? "\n" : "none\n\n");
}

inline void PrintStreams(const StreamCounts& s) {
  std::printf(
      "### StreamUpdates subscribers\n\nsessions %llu, messages %llu (%llu of them full "
      "resends), voxels %llu, sessions of >= 2 s without a message %llu\n\n",
      static_cast<unsigned long long>(s.sessions), static_cast<unsigned long long>(s.messages),
      static_cast<unsigned long long>(s.full_messages), static_cast<unsigned long long>(s.voxels),
      static_cast<unsigned long long>(s.silent_sessions));
}

inline void PrintClouds(const RunResult& r) {
  using C = fusion::v1::SensorCounters;
  std::printf(
      "### Clouds (published by the soak; the rest: ListSensors counters over the run)\n\n"
      "| sensor | points | published | received | DDS lost | dropped (queue) | rejected | "
      "integrated | merged | not integrated | write failures | late ticks |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const auto& s : r.sensors) {
    const auto received = s.Delta(&C::received);
    std::printf(
        "| %s | %zu | %llu | %llu | %lld | %llu | %llu | %llu | %llu | %llu (%.2f %%) | %llu | "
        "%llu |\n",
        s.id.c_str(), s.points_per_frame, static_cast<unsigned long long>(s.published),
        static_cast<unsigned long long>(received),
        static_cast<long long>(s.published) - static_cast<long long>(received),
        static_cast<unsigned long long>(s.Delta(&C::dropped)),
        static_cast<unsigned long long>(s.Delta(&C::rejected)),
        static_cast<unsigned long long>(s.Delta(&C::integrated)),
        static_cast<unsigned long long>(s.Delta(&C::merged)),
        static_cast<unsigned long long>(s.lost()),
        s.published ? 100.0 * static_cast<double>(s.lost()) / static_cast<double>(s.published) : 0,
        static_cast<unsigned long long>(s.write_failures),
        static_cast<unsigned long long>(s.late_ticks));
  }
  const auto& st = r.stats_after;
  std::printf(
      "\nGetStats at the end: version %llu, clouds received %llu, dropped %llu, rejected %llu, "
      "integrated %llu, in map %llu, renders %llu, %llu leaves, map %.1f MB, beam grids %.1f MB, "
      "snapshots saved %llu, failed %llu\n\n",
      static_cast<unsigned long long>(st.map_version()),
      static_cast<unsigned long long>(st.clouds_received()),
      static_cast<unsigned long long>(st.clouds_dropped()),
      static_cast<unsigned long long>(st.clouds_rejected()),
      static_cast<unsigned long long>(st.clouds_integrated()),
      static_cast<unsigned long long>(st.clouds_in_map()),
      static_cast<unsigned long long>(st.renders()),
      static_cast<unsigned long long>(st.map_leaves()),
      static_cast<double>(st.map_memory_bytes()) / 1048576.0,
      static_cast<double>(st.sensor_memory_bytes()) / 1048576.0,
      static_cast<unsigned long long>(st.snapshots_saved()),
      static_cast<unsigned long long>(st.snapshots_failed()));
}

inline void PrintRss(const RunResult& r) {
  std::printf("### fusiond RSS (VmRSS every 10 s, MB)\n\n");
  if (r.rss.empty()) {
    std::printf("not sampled (attached without --fusiond-pid)\n\n");
    return;
  }
  std::string series;
  for (const auto& s : r.rss) {
    char item[48];
    std::snprintf(item, sizeof item, "%s%.0f s %.1f", series.empty() ? "" : ", ", s.t_s, s.rss_mb);
    series += item;
  }
  std::printf("%s\n\n", series.c_str());
  const RssVerdict v = JudgeRss(r.rss);
  if (!v.known) {
    std::printf("flat after the first minute: not known (fewer than two whole minutes after 60 s)\n\n");
    return;
  }
  std::string levels;
  for (const double m : v.minute_medians_mb) {
    char item[24];
    std::snprintf(item, sizeof item, "%s%.1f", levels.empty() ? "" : ", ", m);
    levels += item;
  }
  std::printf(
      "flat after the first minute: **%s** (median RSS of each minute from the second: %s MB; "
      "highest later level %+.1f %% over the second minute's; flat = <= 10 %%)\n"
      "after 60 s: peak %.1f MB (%+.1f %% over the sample at 60 s, %.1f MB), least-squares slope "
      "%+.2f MB/min, mean of the first third of the samples %.1f MB, of the last third %.1f MB\n\n",
      v.flat ? "yes" : "NO", levels.c_str(), v.level_growth_pct, v.max_after_mb, v.growth_pct,
      v.at_60s_mb, v.slope_mb_per_min, v.first_third_mb, v.last_third_mb);
}

inline void PrintFusiondEnd(const RunResult& r) {
  std::printf(
      "CPU over the %.0f s of load: fusiond %.0f s (%.2f cores), soak %.0f s (%.2f cores); "
      "load average at start %s, at end %s\n",
      r.load_s, r.fusiond_cpu_s, r.fusiond_cpu_s / r.load_s, r.soak_cpu_s, r.soak_cpu_s / r.load_s,
      r.load_average_start.c_str(), r.load_average_end.c_str());
  if (!r.own_fusiond) {
    std::printf("\n");
    return;
  }
  std::printf("fusiond exit code after SIGTERM: %d%s\n", r.fusiond_exit_code,
              r.fusiond_died ? " (it had exited during the run)" : "");
  std::printf("fusiond log %s/fusiond.log: %zu warning lines, %zu error lines\n", r.run_dir.c_str(),
              r.log.warnings, r.log.errors);
  for (const auto& line : r.log.first_lines) std::printf("    %s\n", line.c_str());
  std::printf("\n");
}

inline void PrintReport(const RunResult& r) {
  std::printf("\n## Results\n\n");
  PrintRpcTable(r);
  PrintErrors(r);
  PrintStreams(r.streams);
  PrintClouds(r);
  PrintRss(r);
  PrintFusiondEnd(r);
  const auto why = Failures(r);
  std::printf("verdict: %s", why.empty() ? "PASS\n" : "FAIL:");
  for (std::size_t i = 0; i < why.size(); ++i)
    std::printf("%s %s%s", i ? ";" : "", why[i].c_str(), i + 1 == why.size() ? "\n" : "");
}

// ---- JSON -------------------------------------------------------------------------------------

inline std::string Json(const std::string& s) {
  std::string out = "\"";
  for (const unsigned char c : s) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += static_cast<char>(c);
    } else if (c < 0x20) {
      char escape[8];
      std::snprintf(escape, sizeof escape, "\\u%04x", c);
      out += escape;
    } else {
      out += static_cast<char>(c);
    }
  }
  return out + "\"";
}
inline std::string Json(double v) {
  if (!std::isfinite(v)) return "null";
  std::ostringstream out;
  out << v;
  return out.str();
}

inline std::string RpcsJson(const RunResult& r) {
  std::string out = "[";
  for (std::size_t i = 0; i < kRpcCount; ++i) {
    const RpcRecord& rec = r.records[i];
    std::string codes;
    for (const auto& [code, count] : rec.calls_by_code)
      codes += (codes.empty() ? "" : ",") + Json(CodeName(code)) + ":" + std::to_string(count);
    out += std::string(i ? "," : "") + "{\"rpc\":" + Json(RpcName(static_cast<Rpc>(i))) +
           ",\"calls\":" + std::to_string(rec.Count(AnyCode)) +
           ",\"shed\":" + std::to_string(rec.Count(ShedCode)) +
           ",\"errors\":" + std::to_string(rec.Count(ErrorCode)) +
           ",\"p50_ms\":" + Json(Percentile(rec.latency_ms, 0.5)) +
           ",\"p99_ms\":" + Json(Percentile(rec.latency_ms, 0.99)) + ",\"codes\":{" + codes + "}}";
  }
  return out + "]";
}

inline std::string SensorsJson(const RunResult& r) {
  using C = fusion::v1::SensorCounters;
  std::string out = "[";
  for (std::size_t i = 0; i < r.sensors.size(); ++i) {
    const SensorResult& s = r.sensors[i];
    out += std::string(i ? "," : "") + "{\"id\":" + Json(s.id) +
           ",\"published\":" + std::to_string(s.published) +
           ",\"received\":" + std::to_string(s.Delta(&C::received)) +
           ",\"dropped\":" + std::to_string(s.Delta(&C::dropped)) +
           ",\"rejected\":" + std::to_string(s.Delta(&C::rejected)) +
           ",\"integrated\":" + std::to_string(s.Delta(&C::integrated)) +
           ",\"merged\":" + std::to_string(s.Delta(&C::merged)) +
           ",\"not_integrated\":" + std::to_string(s.lost()) + "}";
  }
  return out + "]";
}

inline std::string RssJson(const RunResult& r) {
  std::string series;
  for (const auto& s : r.rss)
    series +=
        (series.empty() ? "" : ",") + std::string("[") + Json(s.t_s) + "," + Json(s.rss_mb) + "]";
  const RssVerdict v = JudgeRss(r.rss);
  std::string levels;
  for (const double m : v.minute_medians_mb) levels += (levels.empty() ? "" : ",") + Json(m);
  return "{\"series_t_s_rss_mb\":[" + series + "],\"at_60s_mb\":" + Json(v.at_60s_mb) +
         ",\"max_after_60s_mb\":" + Json(v.max_after_mb) +
         ",\"slope_after_60s_mb_per_min\":" + Json(v.slope_mb_per_min) +
         ",\"first_third_after_60s_mb\":" + Json(v.first_third_mb) +
         ",\"last_third_after_60s_mb\":" + Json(v.last_third_mb) +
         ",\"minute_medians_mb\":[" + levels + "],\"level_growth_pct\":" +
         Json(v.level_growth_pct) +
         ",\"flat\":" + (v.known ? (v.flat ? "true" : "false") : "null") + "}";
}

inline bool WriteJson(const std::string& path, const RunResult& r) {
  const auto why = Failures(r);
  std::string failures;
  for (const auto& w : why) failures += (failures.empty() ? "" : ",") + Json(w);
  const CloudTotals clouds = SumClouds(r.sensors);
  std::ofstream out(path);
  out << "{\"command\":" << Json(r.command_line) << ",\"date\":" << Json(r.date)
      << ",\"fusiond\":" << Json(r.fusiond_command) << ",\"load_s\":" << Json(r.load_s)
      << ",\"fusiond_cpu_s\":" << Json(r.fusiond_cpu_s) << ",\"soak_cpu_s\":" << Json(r.soak_cpu_s)
      << ",\"load_average_start\":" << Json(r.load_average_start)
      << ",\"load_average_end\":" << Json(r.load_average_end) << ",\"rpcs\":" << RpcsJson(r)
      << ",\"streams\":{\"sessions\":" << r.streams.sessions
      << ",\"messages\":" << r.streams.messages << ",\"voxels\":" << r.streams.voxels
      << "},\"sensors\":" << SensorsJson(r)
      << ",\"clouds_not_integrated_pct\":" << Json(clouds.lost_pct()) << ",\"rss\":" << RssJson(r)
      << ",\"fusiond_exit_code\":" << r.fusiond_exit_code << ",\"failures\":[" << failures
      << "],\"pass\":" << (why.empty() ? "true" : "false") << "}\n";
  return static_cast<bool>(out);
}

}  // namespace fusion::soak
