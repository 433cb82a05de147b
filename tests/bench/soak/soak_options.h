// soak: command-line options and their parsing.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "fusion/clients/cli.h"
#include "soak_recorder.h"

namespace fusion::soak {

// The clients' mix: relative weights (SaveMap and ResetMap come on their schedules instead).
struct Weighted {
  Rpc rpc;
  int weight;
};
inline const std::vector<Weighted> kDefaultMix = {{Rpc::kQueryPoints, 320}, {Rpc::kCastRay, 250},
                                                  {Rpc::kQueryBox, 150},    {Rpc::kGetStats, 100},
                                                  {Rpc::kListSensors, 100}, {Rpc::kInspectBeam, 75},
                                                  {Rpc::kGetSnapshot, 3},   {Rpc::kFindPlanes, 2}};

constexpr const char* kUsage = R"(soak: fusiond under sustained load (issue 14, item 6)

Starts its own fusiond (gRPC on 127.0.0.1, OS-chosen port, a private DDS domain, the
loopback DDS configuration) or attaches to a running one, then for --duration runs:
  * two simulated sensors publishing over DDS while moving along a 20 s lap in front of the
    paper's board: an SR-3000 time-of-flight camera (176 x 144) and a STOC stereo camera;
  * --clients gRPC clients, each looping over a weighted mix of every FusionMap RPC
    (QueryPoints, QueryBox, CastRay, FindPlanes, GetSnapshot, GetStats, ListSensors,
    InspectBeam; SaveMap and ResetMap on a schedule), one connection each;
  * --subscribers StreamUpdates subscribers that connect, stay a random time and leave.
Prints progress every 10 s, then errors by RPC and status code (RESOURCE_EXHAUSTED and
UNAVAILABLE counted apart as "shed"), p50 / p99 latency per RPC, the clouds published /
received / dropped / integrated (ListSensors), and fusiond's RSS every 10 s (VmRSS) with a
"flat after the first minute" verdict.
Exit code 0: no error other than shed, fusiond still up and (own fusiond) exiting 0, and at
most 1 % of the published clouds not integrated; 1 otherwise; 2: bad flags.

Usage: soak [options]
  --duration D          run time: seconds, or with a unit: 90s, 10m, 1h (default 600s)
  --clients N           gRPC query clients (default 16)
  --subscribers N       StreamUpdates subscribers (default 4)
  --stay A-B            each subscription lasts a random A..B seconds (default 1-10)
  --mix RPC=W,...       change weights of the mix (default QueryPoints=320,CastRay=250,
                        QueryBox=150,GetStats=100,ListSensors=100,InspectBeam=75,
                        GetSnapshot=3,FindPlanes=2; 0 leaves an RPC out)
  --think-ms MS         pause of each client after each call (default 20)
  --rate HZ             frames per second of each sensor (default 30)
  --stoc-grid CxR       points per stereo frame (default 160x120, the project's simulated
                        STOC: 640 x 480 pixels as 4 x 4 blocks; 640x480 publishes every pixel)
  --save-every S        one SaveMap every S seconds, by whichever client is due (default 30;
                        0: never)
  --reset-every S       one ResetMap every S seconds (default 120; 0: never): the map empties
                        and the sensors map it again
  --config FILE         fusiond configuration when starting one (default docker/fusiond.pbtxt:
                        listen address, DDS domain and snapshot path are overridden)
  --fusiond PATH        the fusiond binary to start (default: the build's service/fusiond)
  --log-level LEVEL     fusiond's log level (default warn); its log goes to the run folder
  --target HOST:PORT    attach to this fusiond instead of starting one (needs --domain)
  --domain N            DDS domain of --target (default: a private one for the own fusiond)
  --fusiond-pid PID     with --target: the process whose RSS to sample (default: none)
  --sr-id ID --stoc-id ID  sensor ids to publish as (default sr3000, stoc)
  --seed N              random seed of the clients (default 1)
  --json FILE           also write the results as JSON
  --help                this text
)";

struct Options {
  double duration_s = 600;
  std::uint64_t clients = 16;
  std::uint64_t subscribers = 4;
  double stay_min_s = 1, stay_max_s = 10;
  double think_ms = 20;
  double rate_hz = 30;
  int stoc_cols = 160, stoc_rows = 120;
  double save_every_s = 30, reset_every_s = 120;
  std::string config;   // empty: the deployment's
  std::string fusiond;  // empty: the build's
  std::string log_level = "warn";
  std::string target;  // empty: start fusiond
  std::int64_t domain = -1;
  std::int64_t fusiond_pid = -1;
  std::string sr_id = "sr3000", stoc_id = "stoc";
  std::uint64_t seed = 1;
  std::string json_path;
  std::vector<Weighted> mix = kDefaultMix;
};

// "600", "600s", "10m", "1h", "0.5m" -> seconds.
inline fusion::Status ParseDuration(const std::string& text, double* seconds) {
  double scale = 1;
  std::string number = text;
  if (!number.empty()) {
    const char unit = number.back();
    if (unit == 's' || unit == 'm' || unit == 'h') {
      scale = unit == 's' ? 1 : unit == 'm' ? 60 : 3600;
      number.pop_back();
    }
  }
  double value = 0;
  if (auto s = clients::ParseDouble("--duration", number, &value); !s.ok()) return s;
  if (!(value > 0)) return fusion::Status::Error("--duration must be positive");
  *seconds = value * scale;
  return fusion::Status::Ok();
}

// "A-B" (seconds, A <= B) or "AxB" (integers).
inline bool SplitPair(const std::string& text, char separator, std::string* a, std::string* b) {
  const auto at = text.find(separator);
  if (at == std::string::npos) return false;
  *a = text.substr(0, at);
  *b = text.substr(at + 1);
  return true;
}

inline fusion::Status ParseStay(const std::string& text, Options* o) {
  std::string a, b;
  if (!SplitPair(text, '-', &a, &b)) return fusion::Status::Error("--stay: expected A-B");
  if (auto s = clients::ParseDouble("--stay", a, &o->stay_min_s); !s.ok()) return s;
  if (auto s = clients::ParseDouble("--stay", b, &o->stay_max_s); !s.ok()) return s;
  if (!(o->stay_min_s > 0 && o->stay_min_s <= o->stay_max_s))
    return fusion::Status::Error("--stay: need 0 < A <= B");
  return fusion::Status::Ok();
}

inline fusion::Status ParseGrid(const std::string& text, Options* o) {
  std::string a, b;
  std::uint64_t cols = 0, rows = 0;
  if (!SplitPair(text, 'x', &a, &b)) return fusion::Status::Error("--stoc-grid: expected CxR");
  if (auto s = clients::ParseUint("--stoc-grid", a, &cols); !s.ok()) return s;
  if (auto s = clients::ParseUint("--stoc-grid", b, &rows); !s.ok()) return s;
  if (cols < 1 || rows < 1 || cols > 4096 || rows > 4096)
    return fusion::Status::Error("--stoc-grid: 1..4096 each");
  o->stoc_cols = static_cast<int>(cols);
  o->stoc_rows = static_cast<int>(rows);
  return fusion::Status::Ok();
}

// "QueryPoints=500,FindPlanes=0": weights of the named RPCs of the mix.
inline fusion::Status ParseMix(const std::string& text, Options* o) {
  std::size_t at = 0;
  while (at <= text.size()) {
    const std::size_t end = std::min(text.find(',', at), text.size());
    std::string name, weight_text;
    if (!SplitPair(text.substr(at, end - at), '=', &name, &weight_text))
      return fusion::Status::Error("--mix: expected RPC=WEIGHT,...");
    std::uint64_t weight = 0;
    if (auto s = clients::ParseUint("--mix", weight_text, &weight); !s.ok()) return s;
    auto it = std::find_if(o->mix.begin(), o->mix.end(),
                           [&](const Weighted& w) { return name == RpcName(w.rpc); });
    if (it != o->mix.end()) it->weight = static_cast<int>(std::min<std::uint64_t>(weight, 1000000));
    if (it == o->mix.end())
      return fusion::Status::Error("--mix: '" + name + "' is not an RPC of the mix");
    at = end + 1;
  }
  int total = 0;
  for (const Weighted& w : o->mix) total += w.weight;
  if (total <= 0) return fusion::Status::Error("--mix: every weight is 0");
  return fusion::Status::Ok();
}

inline fusion::Status ParseInt(const std::string& flag, const std::string& v, std::int64_t* out) {
  std::uint64_t u = 0;
  if (auto s = clients::ParseUint(flag, v, &u); !s.ok()) return s;
  *out = static_cast<std::int64_t>(u);
  return fusion::Status::Ok();
}

// One flag with its value.
inline fusion::Status ParseFlag(const std::string& flag, const std::string& v, Options* o) {
  using clients::ParseDouble;
  using clients::ParseUint;
  if (flag == "--duration") return ParseDuration(v, &o->duration_s);
  if (flag == "--clients") return ParseUint(flag, v, &o->clients);
  if (flag == "--subscribers") return ParseUint(flag, v, &o->subscribers);
  if (flag == "--stay") return ParseStay(v, o);
  if (flag == "--mix") return ParseMix(v, o);
  if (flag == "--think-ms") return ParseDouble(flag, v, &o->think_ms);
  if (flag == "--rate") return ParseDouble(flag, v, &o->rate_hz);
  if (flag == "--stoc-grid") return ParseGrid(v, o);
  if (flag == "--save-every") return ParseDouble(flag, v, &o->save_every_s);
  if (flag == "--reset-every") return ParseDouble(flag, v, &o->reset_every_s);
  if (flag == "--seed") return ParseUint(flag, v, &o->seed);
  if (flag == "--domain") return ParseInt(flag, v, &o->domain);
  if (flag == "--fusiond-pid") return ParseInt(flag, v, &o->fusiond_pid);
  std::string* text = flag == "--config"      ? &o->config
                      : flag == "--fusiond"   ? &o->fusiond
                      : flag == "--log-level" ? &o->log_level
                      : flag == "--target"    ? &o->target
                      : flag == "--sr-id"     ? &o->sr_id
                      : flag == "--stoc-id"   ? &o->stoc_id
                      : flag == "--json"      ? &o->json_path
                                              : nullptr;
  if (text == nullptr) return fusion::Status::Error("unknown flag " + flag);
  *text = v;
  return fusion::Status::Ok();
}

inline fusion::Status CheckOptions(const Options& o) {
  if (o.clients > 1000 || o.subscribers > 1000)
    return fusion::Status::Error("--clients and --subscribers: at most 1000");
  if (!(o.rate_hz > 0 && o.rate_hz <= 1000)) return fusion::Status::Error("--rate: (0, 1000]");
  if (!(o.think_ms >= 0)) return fusion::Status::Error("--think-ms must be >= 0");
  if (!(o.save_every_s >= 0 && o.reset_every_s >= 0))
    return fusion::Status::Error("--save-every and --reset-every must be >= 0");
  if (o.domain > 230) return fusion::Status::Error("--domain must be 0..230");
  if (!o.target.empty() && o.domain < 0)
    return fusion::Status::Error("--target needs --domain (the target's DDS domain)");
  if (!o.target.empty() && (!o.fusiond.empty() || !o.config.empty()))
    return fusion::Status::Error("--fusiond and --config start a fusiond: not with --target");
  if (o.target.empty() && o.fusiond_pid >= 0)
    return fusion::Status::Error("--fusiond-pid goes with --target");
  return fusion::Status::Ok();
}

// Returns 0 to go on, else the exit code (0 after --help is reported as -1: exit 0).
inline int ParseOptions(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "--help" || flag == "-h") {
      std::fputs(kUsage, stdout);
      return -1;
    }
    if (i + 1 >= argc) {
      std::fprintf(stderr, "soak: %s needs a value (see soak --help)\n", flag.c_str());
      return 2;
    }
    if (auto s = ParseFlag(flag, argv[++i], o); !s.ok()) {
      std::fprintf(stderr, "soak: %s (see soak --help)\n", s.message().c_str());
      return 2;
    }
  }
  if (auto s = CheckOptions(*o); !s.ok()) {
    std::fprintf(stderr, "soak: %s (see soak --help)\n", s.message().c_str());
    return 2;
  }
  return 0;
}

}  // namespace fusion::soak
