// Environment throughput on one core: steps per second at 128x128 and 64x64 with 20 traffic
// vehicles, and where the time goes (SUMO + traffic upkeep, rendering, events + rewards).
// The ego follows the town's right loop at 5 m/s so episodes last; episode resets (a SUMO
// reload) are timed separately because they happen once per episode, not per step.
//
//   env_bench [--town town01] [--steps 3000] [--density 20] [--mode libsumo|libtraci]
#include <time.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <opencv2/core.hpp>
#include <string>

#include "indrive/basics/log.h"
#include "indrive/envserver/env.h"
#include "indrive/envserver/follower.h"

namespace {

using namespace indrive::env;

double thread_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// The per-step figure is CPU time of this thread (resets excluded), so it means "one core"
// even on a busy machine; the split into parts comes from the Env's wall-clock timers and is
// scaled to that CPU time.
void run(Env& env, int steps, int size, int density) {
  double reset_cpu_s = 0.0;
  int resets = 0;
  int done = 0;
  const EnvTiming before = env.timing();
  const double cpu_start = thread_cpu_s();
  while (done < steps) {
    const double reset_start = thread_cpu_s();
    StepResult r = env.reset({.route = "right_loop",
                              .density = density,
                              .traffic_seed = static_cast<std::uint64_t>(resets + 1)});
    reset_cpu_s += thread_cpu_s() - reset_start;
    ++resets;
    WaypointFollower follower(*env.route(), env.config().ego, {.target_speed_mps = 5.0});
    follower.reset();
    while (!r.is_last && done < steps) {
      r = env.step(follower.act(env.ego()));
      ++done;
    }
  }
  const double step_cpu_s = thread_cpu_s() - cpu_start - reset_cpu_s;
  const EnvTiming& t = env.timing();
  const double sumo = t.sumo_s - before.sumo_s;
  const double traffic = t.traffic_s - before.traffic_s;
  const double render = t.render_s - before.render_s;
  const double events = t.events_s - before.events_s;
  const double wall = sumo + traffic + render + events;
  const double us = 1e6 * step_cpu_s / done;  // CPU microseconds per step
  std::printf(
      "%3dx%-3d  %6.0f steps/s on one core (%6.1f us/step: sumo %5.1f%%, traffic %4.1f%%, "
      "render %5.1f%%, events %4.1f%%)  %d resets, %.1f ms CPU each\n",
      size, size, done / step_cpu_s, us, 100 * sumo / wall, 100 * traffic / wall,
      100 * render / wall, 100 * events / wall, resets, 1e3 * reset_cpu_s / resets);
}

}  // namespace

int main(int argc, char** argv) {
  std::string town = "town01";
  std::string mode = "libsumo";
  int steps = 3000;
  int density = 20;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    if (flag == "--town") {
      town = argv[i + 1];
    } else if (flag == "--steps") {
      steps = std::atoi(argv[i + 1]);
    } else if (flag == "--mode") {
      mode = argv[i + 1];
    } else if (flag == "--density") {
      density = std::atoi(argv[i + 1]);
    } else {
      std::fprintf(stderr, "env_bench: unknown flag %s\n", flag.c_str());
      return 2;
    }
  }
  indrive::log::set_level(indrive::log::Level::kWarn);
  cv::setNumThreads(1);  // one core: the figure is per environment process
  try {
    std::printf("env_bench: %s, %s, density %d, follower at 5 m/s, %d steps per size\n",
                town.c_str(), mode.c_str(), density, steps);
    // libsumo allows one simulation per process: one Env, camera size set per run by a new
    // Env only in libtraci mode. Both sizes share the SUMO part, so run 128 then 64 through
    // separate Envs when possible.
    for (int size : {128, 64}) {
      EnvConfig config;
      config.town = town;
      config.sumo.mode = parse_sumo_mode(mode);
      config.camera.width = size;
      config.camera.height = size;
      config.events.time_limit_steps = 100000;
      Env env(config);
      run(env, steps, size, density);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "env_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
