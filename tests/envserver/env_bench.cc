// Environment throughput on one core: steps per second at 128x128 and 64x64 with 20 traffic
// vehicles, and where the time goes (SUMO + traffic upkeep, rendering, events + rewards).
// The ego follows the town's right loop at 5 m/s so episodes last; episode resets (a SUMO
// reload) are timed separately because they happen once per episode, not per step.
//
//   env_bench [--town town01] [--steps 3000] [--density 20] [--mode libsumo|libtraci]
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <opencv2/core.hpp>
#include <string>

#include "indrive/common/log.h"
#include "indrive/envserver/env.h"
#include "indrive/envserver/follower.h"

namespace {

using namespace indrive::env;

void run(Env& env, int steps, int size, int density) {
  const auto start = std::chrono::steady_clock::now();
  double reset_s = 0.0;
  int resets = 0;
  int done = 0;
  const EnvTiming before = env.timing();
  while (done < steps) {
    const auto reset_start = std::chrono::steady_clock::now();
    StepResult r = env.reset({.route = "right_loop",
                              .density = density,
                              .traffic_seed = static_cast<std::uint64_t>(resets + 1)});
    reset_s +=
        std::chrono::duration<double>(std::chrono::steady_clock::now() - reset_start).count();
    ++resets;
    WaypointFollower follower(*env.route(), env.config().ego, {.target_speed_mps = 5.0});
    follower.reset();
    while (!r.is_last && done < steps) {
      r = env.step(follower.act(env.ego()));
      ++done;
    }
  }
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const EnvTiming& t = env.timing();
  const double sumo = t.sumo_s - before.sumo_s;
  const double traffic = t.traffic_s - before.traffic_s;
  const double render = t.render_s - before.render_s;
  const double events = t.events_s - before.events_s;
  const double step_s = sumo + traffic + render + events;
  std::printf(
      "%3dx%-3d  %6.0f steps/s  (%6.1f us/step: sumo %6.1f, traffic %5.1f, render %6.1f, "
      "events %5.1f)  "
      "%d resets, %.1f ms each; %.0f steps/s including resets\n",
      size, size, done / step_s, 1e6 * step_s / done, 1e6 * sumo / done, 1e6 * traffic / done,
      1e6 * render / done, 1e6 * events / done, resets, 1e3 * reset_s / resets, done / wall_s);
}

}  // namespace

int main(int argc, char** argv) {
  std::string town = "town01";
  std::string mode = "libsumo";
  int steps = 3000;
  int density = 20;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    if (flag == "--town")
      town = argv[i + 1];
    else if (flag == "--steps")
      steps = std::atoi(argv[i + 1]);
    else if (flag == "--mode")
      mode = argv[i + 1];
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
