// deploy/experiments/learner_speed.sh: its report from the benchmarks' logs (--report-only), each
// figure against its target and the bound of the machine's product peak, and its refusals.
#include <gtest/gtest.h>

#include <chrono>

#include "child_process.h"
#include "testing.h"

namespace indrive {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

const fs::path kScript = fs::path(INDRIVE_SOURCE_DIR) / "deploy/experiments/learner_speed.sh";

using testing::write_text;

// The lines of a common_agent_bench run that the report reads.
std::string bench_log(double seconds, double gflop, double fp32_peak, double bf16_peak = 0,
                      const std::string& auto_chose = "") {
  return "kernels: oneDNN 2.6.3 on avx512_core_bf16; products bf16 on AVX512_BF16\n" +
         (auto_chose.empty()
              ? std::string()
              : "precision_choice chosen=" + auto_chose +
                    " fp32_update_s=0.05 bf16_update_s=0.04 (precision auto: ...)\n") +
         "product_peak fp32_gflops=" + std::to_string(fp32_peak) +
         " bf16_gflops=" + std::to_string(bf16_peak) +
         "\npreset=x method=disag threads=2 B=16 T=64 H=15\n"
         "agent_update sec=" +
         std::to_string(seconds) +
         " cpu_sec=1 page_faults=0 frames_per_sec=1\n"
         "agent_update_total gflop=" +
         std::to_string(gflop) + " gflops=1 of_fp32_peak=1% of_bf16_peak=1%\n";
}

int run_script(const std::vector<std::string>& args, const fs::path& log) {
  std::vector<std::string> argv = {"/bin/bash", kScript.string()};
  argv.insert(argv.end(), args.begin(), args.end());
  testing::Child child(argv, log);
  return child.wait(60s);
}

// A machine with bf16: both precisions are reported; medians of three runs; every verdict
// follows its target's direction; a missing log reads "not measured".
TEST(LearnerSpeedReport, EveryFigureAgainstItsTargetFromTheLogs) {
  testing::TempDir dir;
  const fs::path out = dir.path() / "speed", logs = out / "logs";
  write_text(logs / "machine.txt",
             "cpu: Test CPU\nthreads: 2\nload: 0.05\nfeatures: avx2 avx512f avx512_bf16 \n"
             "started: 2026-12-06 10:00 UTC\n");
  write_text(logs / "probe.txt",
             "kernels: oneDNN 2.6.3 on avx512_core_bf16; products bf16 on AVX512_BF16\n");
  // tiny fp32 at 2 threads: median 0.045 (not met); bf16: median 0.035 (met).
  const double tiny_fp32[] = {0.050, 0.045, 0.030}, tiny_bf16[] = {0.035, 0.020, 0.039};
  const double cpu_fp32[] = {1.9, 2.1, 2.0}, cpu_bf16[] = {0.9, 0.7, 0.8};
  for (int i = 0; i < 3; ++i) {
    const std::string n = std::to_string(i + 1);
    write_text(logs / ("tiny-fp32-t2-" + n + ".txt"), bench_log(tiny_fp32[i], 5.3, 400, 650));
    write_text(logs / ("tiny-bf16-t2-" + n + ".txt"), bench_log(tiny_bf16[i], 5.3, 400, 650));
    write_text(logs / ("tiny-fp32-t1-" + n + ".txt"), bench_log(0.06, 5.3, 200, 320));
    write_text(logs / ("tiny-bf16-t1-" + n + ".txt"), bench_log(0.05, 5.3, 200, 320));
    write_text(logs / ("cpu-fp32-t2-" + n + ".txt"), bench_log(cpu_fp32[i], 282, 400, 650));
    write_text(logs / ("cpu-bf16-t2-" + n + ".txt"), bench_log(cpu_bf16[i], 282, 400, 650));
    // auto: bf16 where it chose bf16, fp32 at 1 thread, where it chose fp32 and was slower.
    write_text(logs / ("tiny-auto-t2-" + n + ".txt"),
               bench_log(tiny_bf16[i], 5.3, 400, 650, "bf16"));
    write_text(logs / ("tiny-auto-t1-" + n + ".txt"), bench_log(0.06, 5.3, 200, 320, "fp32"));
    write_text(logs / ("cpu-auto-t2-" + n + ".txt"),
               bench_log(cpu_bf16[i], 282, 400, 650, i == 0 ? "fp32" : "bf16"));
  }
  // The paper's model: one run per precision, with its peak memory.
  write_text(logs / "small-fp32-t2-1.txt",
             bench_log(11.8, 2331, 400, 650) + "max_rss_kb=13000000\n");
  write_text(logs / "small-bf16-t2-1.txt", bench_log(8.0, 2331, 400, 650));
  write_text(logs / "small-auto-t2-1.txt", bench_log(8.1, 2331, 400, 650, "bf16"));
  write_text(logs / "torch-cpu.txt", "torch_ratio torch_sec=20.0 ours_sec=1.25 speedup=16.0x\n");
  write_text(logs / "service.txt",
             "scenario                     window_s  env_steps/s  per_actor  updates/s\n"
             "tiny rate-limited, 1 actor       30.1         95.0       95.0     23.7\n"
             "tiny rate-limited, 2 actors      30.0         80.0       40.0     20.0\n"
             "cpu rate-limited, 1 actor        90.2         30.0       30.0      0.9\n");
  const fs::path log = dir.path() / "report.log";
  ASSERT_EQ(run_script({"--out", out.string(), "--report-only"}, log), 0) << testing::slurp(log);
  const std::string report = testing::slurp(out / "report.md");
  const std::string csv = testing::slurp(out / "figures.csv");
  auto has = [&](const std::string& text, const std::string& line) {
    EXPECT_NE(text.find(line), std::string::npos) << "missing: " << line << "\nin:\n" << text;
  };
  has(report, "# Learner speed on Test CPU (avx2 avx512f avx512_bf16)");
  has(report, "Medians of 3 runs");
  has(report, "| full agent update | tiny, fp32, 2 threads | 0.045 s | <= 0.04 s | not met |");
  has(report, "| full agent update | tiny, bf16, 2 threads | 0.035 s | <= 0.04 s | met |");
  has(report, "| full agent update | tiny, bf16, 1 thread | 0.05 s |  | no target |");
  has(report, "| full agent update | cpu, fp32, 2 threads | 2 s | <= 0.8 s | not met |");
  has(report, "| full agent update | cpu, bf16, 2 threads | 0.8 s | <= 0.8 s | met |");
  // What auto chose in each run, and its update against the faster forced precision.
  has(report,
      "| full agent update | tiny, auto (chose bf16 3x), 2 threads | 0.035 s | <= 0.04 s | met |");
  has(report, "| full agent update | cpu, auto (chose bf16 2x, fp32 1x), 2 threads | 0.8 s |");
  has(report,
      "| auto over the faster forced precision | tiny, 2 threads | 1.000 x | <= 1.05 x | met |");
  has(report,
      "| auto over the faster forced precision | tiny, 1 thread | 1.200 x | <= 1.05 x | not met |");
  EXPECT_EQ(report.find("| tiny auto, 2 threads |"), std::string::npos) << "no bound row for auto";
  // The bound: the update's product GFLOP over the peak of its precision.
  has(report, "| cpu bf16, 2 threads | 282.000000 | 650.000000 | 0.434 |");
  has(report, "| cpu fp32, 2 threads | 282.000000 | 400.000000 | 0.705 |");
  // small: the update, its bound, memory and the learner's hours at ratio 32 (1024 frames a
  // batch: 3,125 updates for 1e5 env steps).
  has(report, "| fp32 | 11.800000 | 2331.000000 | 5.83 | 12.4 | 10.2 | 51.2 |");
  has(report, "| bf16 | 8.000000 | 2331.000000 | 3.59 | - | 6.9 | 34.7 |");
  has(report, "| auto (chose bf16) | 8.100000 | 2331.000000 | 3.59 | - | 7.0 | 35.2 |");
  // PyTorch: the cpu ratio has the target; tiny was not run.
  has(report, "| times faster than PyTorch | cpu, auto, 2 threads | 16.0 x | >= 15 x | met |");
  has(report, "| times faster than PyTorch | tiny, auto, 2 threads | - x |  | not measured |");
  // Service: steps/s at least 90, hours 5e5 / rate.
  has(report, "| env steps/s at ratio 32 | tiny, 1 actor | 95.0 steps/s | >= 90 steps/s | met |");
  has(report, "| hours for 5e5 env steps | tiny, 1 actor | 1.46 h | <= 1.5 h | met |");
  has(report,
      "| env steps/s at ratio 32 | tiny, 2 actors | 80.0 steps/s | >= 90 steps/s | not met |");
  has(report, "| hours for 5e5 env steps | cpu, 1 actor | 4.63 h | <= 4 h | not met |");
  has(csv, "full agent update,\"cpu, bf16, 2 threads\",0.8,s,0.8,met\n");
  has(csv, "hours for 5e5 env steps,\"tiny, 2 actors\",1.74,h,1.5,not met\n");
}

// Without native bf16 only fp32 is reported; without a service log, no service table.
TEST(LearnerSpeedReport, AMachineWithoutBf16ReportsFp32Only) {
  testing::TempDir dir;
  const fs::path out = dir.path() / "speed", logs = out / "logs";
  write_text(
      logs / "machine.txt",
      "cpu: Old CPU\nthreads: 2\nload: 0.1\nfeatures: avx2 \nstarted: 2026-12-06 11:00 UTC\n");
  write_text(logs / "probe.txt",
             "kernels: oneDNN 2.6.3 on avx2; products fp32 (no native bf16 on this CPU)\n");
  for (const char* run : {"tiny-fp32-t2-1", "tiny-fp32-t1-1", "cpu-fp32-t2-1"})
    write_text(logs / (std::string(run) + ".txt"), bench_log(1.5, 282, 176));
  const fs::path log = dir.path() / "report.log";
  ASSERT_EQ(run_script({"--out", out.string(), "--report-only", "--repeats", "1"}, log), 0)
      << testing::slurp(log);
  const std::string report = testing::slurp(out / "report.md");
  EXPECT_EQ(report.find("bf16,"), std::string::npos) << report;
  EXPECT_NE(report.find("Medians of 1 runs"), std::string::npos) << report;
  EXPECT_NE(
      report.find("| full agent update | cpu, fp32, 2 threads | 1.5 s | <= 0.8 s | not met |"),
      std::string::npos)
      << report;
  EXPECT_NE(report.find("| cpu fp32, 2 threads | 282.000000 | 176.000000 | 1.602 |"),
            std::string::npos)
      << report;
  EXPECT_EQ(report.find("Service at replay ratio 32"), std::string::npos) << report;
}

TEST(LearnerSpeedReport, RefusesWhatItCannotRunAndSaysWhy) {
  testing::TempDir dir;
  const fs::path log = dir.path() / "refused.log";
  EXPECT_EQ(run_script({"--out", (dir.path() / "empty").string(), "--report-only"}, log), 2);
  EXPECT_NE(testing::slurp(log).find("no earlier run in"), std::string::npos)
      << testing::slurp(log);
  EXPECT_EQ(run_script({"--repeats", "0", "--report-only", "--out", dir.path().string()}, log), 2);
  EXPECT_NE(testing::slurp(log).find("--repeats wants a positive count"), std::string::npos);
  EXPECT_EQ(run_script({"--bin", (dir.path() / "nothing").string()}, log), 1);
  EXPECT_NE(testing::slurp(log).find("build with the benchmarks first"), std::string::npos);
  EXPECT_EQ(run_script({"--frobnicate"}, log), 2);
  EXPECT_NE(testing::slurp(log).find("unknown option --frobnicate"), std::string::npos);
}

}  // namespace
}  // namespace indrive
