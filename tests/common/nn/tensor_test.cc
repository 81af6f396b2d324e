// Shapes, the graph's arena and backward pass, no-grad mode, parameters and the RNG.
#include "indrive/nn/tensor.h"

#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <set>
#include <span>
#include <stdexcept>
#include <thread>
#include <utility>
#include <vector>

#include "indrive/nn/nn.h"

namespace indrive::nn {
namespace {

// The unit tests run the engine on one thread: results are then bitwise reproducible, and on
// a machine shared with other jobs, parallel regions would only add waiting. The threading
// test below switches to two threads explicitly.
const bool kSingleThreaded = (set_threads(1), true);

TEST(ShapeTest, DimensionsRowsAndCols) {
  Shape s{16, 64, 3};
  EXPECT_EQ(s.rank, 3);
  EXPECT_EQ(s.numel(), 16 * 64 * 3);
  EXPECT_EQ(s.rows(), 16 * 64);
  EXPECT_EQ(s.cols(), 3);
  EXPECT_EQ(s[-1], 3);
  EXPECT_EQ(s.str(), "(16, 64, 3)");
  EXPECT_EQ(Shape().numel(), 1);
  EXPECT_NE(s, (Shape{16, 64, 4}));
}

TEST(GraphTest, GradientsAccumulateOverUsesAndCalls) {
  Graph& g = current_graph();
  g.reset();
  ParamGroup group("g");
  Parameter& p = group.add("p", Shape{3});
  for (float& v : p.value()) v = 2.0f;
  // d/dp sum(p * p + p) = 2p + 1 = 5.
  Tensor x = p.tensor();
  g.backward(sum(add(mul(x, x), x)));
  for (float v : p.grad()) EXPECT_FLOAT_EQ(v, 5.0f);
  // A second graph adds to the same parameter gradient until zero_grad.
  g.reset();
  g.backward(sum(p.tensor()));
  for (float v : p.grad()) EXPECT_FLOAT_EQ(v, 6.0f);
  group.zero_grad();
  for (float v : p.grad()) EXPECT_EQ(v, 0.0f);
}

TEST(GraphTest, NoGradModeRecordsNothing) {
  Graph& g = current_graph();
  g.reset();
  ParamGroup group("g");
  Parameter& p = group.add("p", Shape{2, 2});
  for (float& v : p.value()) v = 1.5f;
  Tensor y;
  {
    NoGradGuard no_grad;
    EXPECT_FALSE(g.grad_enabled());
    y = sum(tanh(p.tensor()));
  }
  EXPECT_TRUE(g.grad_enabled());
  EXPECT_FALSE(y.requires_grad());
  EXPECT_NEAR(y.item(), 4 * std::tanh(1.5f), 1e-6f);
  g.backward(y);  // nothing to do
  for (float v : p.grad()) EXPECT_EQ(v, 0.0f);
}

TEST(GraphTest, ConstantsGetNoGradient) {
  Graph& g = current_graph();
  g.reset();
  Tensor c = full({2}, 3.0f);
  Tensor leaf = grad_leaf({2}, std::vector<float>{1.0f, 2.0f});
  g.backward(sum(mul(c, leaf)));
  EXPECT_EQ(c.grad(), nullptr);
  ASSERT_NE(leaf.grad(), nullptr);
  EXPECT_FLOAT_EQ(leaf.grad()[0], 3.0f);
}

// One small training step's worth of ops.
void training_step(Mlp& net, Adam& adam, int rows) {
  Graph& g = current_graph();
  g.reset();
  Tensor x = full({rows, 8}, 0.25f);
  Tensor y = full({rows, 1}, 1.0f);
  g.backward(mse(net(x), y));
  adam.step();
}

TEST(GraphTest, SteadyStateStepsDoNotAllocate) {
  Rng rng(1);
  ParamGroup group("model");
  Mlp net(group, "net", 8, {.units = 64, .layers = 3, .out = 1}, rng);
  Adam adam(group, {});
  Graph& g = current_graph();
  // A step larger than the arena's first block forces growth; reset then merges the blocks.
  training_step(net, adam, 20000);
  training_step(net, adam, 20000);
  const std::size_t allocations = g.arena_system_allocations();
  const std::size_t capacity = g.arena_capacity_bytes();
  for (int i = 0; i < 5; ++i) training_step(net, adam, 20000);
  EXPECT_EQ(g.arena_system_allocations(), allocations);
  EXPECT_EQ(g.arena_capacity_bytes(), capacity);
  EXPECT_GT(g.num_nodes(), 10u);
  g.reset();
  EXPECT_EQ(g.arena_used_bytes(), 0u);
}

// A small model that touches every kind of op an agent update uses: conv encoder and decoder,
// GRU, LayerNorm + SiLU, categorical sampling (softmax), concat and slice, losses and Adam.
struct ReuseModel {
  explicit ReuseModel(Rng& rng)
      : group("m"),
        enc(group, "enc", {.image = 16, .channels = 3, .depth = 4, .min_res = 4}, rng),
        gru(group, "gru", enc.embed_dim() + 8 * 4, 16, rng),
        post(group, "post", 16, {.units = 16, .layers = 1, .out = 8 * 4}, rng),
        dec(group, "dec", 16, {.image = 16, .channels = 3, .depth = 4, .min_res = 4}, rng),
        adam(group, {.lr = 1e-3f}) {}

  // One training update on a fixed batch (4 steps of 2 images); returns the loss.
  float update(Rng& rng) {
    Graph& g = current_graph();
    g.reset();
    std::vector<float> pixels(8 * 16 * 16 * 3);
    for (std::size_t i = 0; i < pixels.size(); ++i) pixels[i] = static_cast<float>(i % 7) / 7.0f;
    Tensor images = constant({8, 16, 16, 3}, pixels);
    Tensor embed = enc(images);
    Tensor h = zeros({2, 16}), z = zeros({2, 8 * 4});
    std::vector<Tensor> feats;
    for (int t = 0; t < 4; ++t) {
      h = gru(concat({slice(embed, 2 * t, 2 * t + 2, 0), z}, -1), h);
      z = sample_straight_through(unimix_probs(post(h), 4), 4, rng);
      feats.push_back(h);
    }
    Tensor recon = dec(concat(feats, 0));
    Tensor loss = add(mse(recon, images), mean(entropy(reshape(softmax(z), {16, 4}))));
    g.backward(loss);
    adam.step();
    return loss.item();
  }

  ParamGroup group;
  ConvEncoder enc;
  GruCell gru;
  Mlp post;
  ConvDecoder dec;
  Adam adam;
};

// Fills every byte of the arena that the next step can get with NaN, so that an op reading
// memory it did not write (relying on fresh pages being zero) changes the results.
void poison_arena() {
  Graph& g = current_graph();
  g.reset();
  constexpr std::int64_t kPiece = 64;  // floats; block sizes are multiples of this
  while (g.arena_used_bytes() + kPiece * sizeof(float) <= g.arena_capacity_bytes())
    std::fill_n(g.alloc(kPiece), kPiece, std::nanf(""));
  g.reset();
}

// Losses of three updates and the parameters after them; `fresh` gives every update newly
// mapped memory, otherwise the arena's kept blocks are reused (after poisoning them).
std::vector<float> reuse_run(bool fresh) {
  Rng rng(5);
  ReuseModel model(rng);
  std::vector<float> out;
  for (int step = 0; step < 3; ++step) {
    if (fresh)
      current_graph().release_memory();
    else
      poison_arena();
    out.push_back(model.update(rng));
  }
  for (const auto& p : model.group.params())
    out.insert(out.end(), p->value().begin(), p->value().end());
  current_graph().reset();
  return out;
}

TEST(GraphTest, ReusedArenaGivesBitwiseTheResultsOfFreshMemory) {
  const std::vector<float> fresh = reuse_run(true);
  const std::vector<float> reused = reuse_run(false);
  ASSERT_EQ(fresh.size(), reused.size());
  for (float v : reused) ASSERT_TRUE(std::isfinite(v));
  EXPECT_EQ(std::memcmp(fresh.data(), reused.data(), fresh.size() * sizeof(float)), 0);
}

TEST(GraphTest, ArenaKeepsItsBlocksAndAddressesAcrossUpdates) {
  Rng rng(6);
  ReuseModel model(rng);
  Graph& g = current_graph();
  g.release_memory();
  model.update(rng);
  const std::size_t allocations = g.arena_system_allocations();
  const std::size_t capacity = g.arena_capacity_bytes();
  const std::size_t used = g.arena_used_bytes();
  EXPECT_GT(allocations, 0u);
  for (int i = 0; i < 3; ++i) {
    model.update(rng);
    // The same step takes the same memory: the pool neither grows nor moves.
    EXPECT_EQ(g.arena_system_allocations(), allocations);
    EXPECT_EQ(g.arena_capacity_bytes(), capacity);
    EXPECT_EQ(g.arena_used_bytes(), used);
  }
  g.reset();
  const float* first = zeros({1000}).data();
  g.reset();
  EXPECT_EQ(zeros({1000}).data(), first);
  // A step larger than everything kept adds blocks; a smaller one reuses the first ones.
  g.reset();
  g.alloc(static_cast<std::int64_t>(capacity));
  EXPECT_GT(g.arena_system_allocations(), allocations);
  const std::size_t grown = g.arena_capacity_bytes();
  g.reset();
  EXPECT_EQ(zeros({1000}).data(), first);
  EXPECT_EQ(g.arena_capacity_bytes(), grown);
  g.release_memory();
  EXPECT_EQ(g.arena_capacity_bytes(), 0u);
  EXPECT_EQ(g.arena_high_water_bytes(), 0u);
}

TEST(GraphTest, RewindGivesBackScratchMemoryOfNoGradWork) {
  Graph& g = current_graph();
  g.reset();
  Tensor kept = full({4}, 2.0f);
  float total = 0.0f;
  const std::size_t used = g.arena_used_bytes();
  const float* first_scratch = nullptr;
  {
    NoGradGuard no_grad;
    for (int chunk = 0; chunk < 3; ++chunk) {
      const Graph::Mark mark = g.mark();
      // Larger than the first block, so the scratch spills into a second one.
      Tensor scratch = add_scalar(full({5 << 20}, static_cast<float>(chunk)), kept.data()[0]);
      if (chunk == 0) first_scratch = scratch.data();
      EXPECT_EQ(scratch.data(), first_scratch);  // every chunk reuses the same memory
      total += scratch.data()[123];
      g.rewind(mark);
      EXPECT_EQ(g.arena_used_bytes(), used);
    }
  }
  EXPECT_EQ(total, 2.0f + 3.0f + 4.0f);
  EXPECT_EQ(kept.data()[3], 2.0f);  // tensors from before the mark are untouched
  // Recorded ops cannot be rewound: their backward rules would read freed memory.
  const Graph::Mark mark = g.mark();
  Tensor leaf = grad_leaf({2}, std::vector<float>{1.0f, 2.0f});
  [[maybe_unused]] Tensor y = square(leaf);
  EXPECT_DEATH(g.rewind(mark), "rewind");
  g.reset();
}

// Forward and backward of a small conv + norm + linear model; returns the loss and all grads.
std::vector<float> conv_model_grads(int threads) {
  set_threads(threads);
  Rng rng(21);
  ParamGroup group("m");
  ConvEncoder enc(group, "enc", {.image = 32, .channels = 3, .depth = 8, .min_res = 4}, rng);
  Linear head(group, "head", enc.embed_dim(), 3, {}, rng);
  std::vector<float> images(32 * 32 * 32 * 3);
  for (float& v : images) v = rng.uniform();
  Graph& g = current_graph();
  g.reset();
  Tensor loss = mean(square(head(enc(constant({32, 32, 32, 3}, images)))));
  g.backward(loss);
  std::vector<float> out = {loss.item()};
  for (const auto& p : group.params()) out.insert(out.end(), p->grad().begin(), p->grad().end());
  g.reset();
  set_threads(1);
  return out;
}

// After set_threads, every engine thread flushes denormals: a product below the smallest normal
// float comes out 0 (FTZ), and a denormal input counts as 0 (DAZ), on each of the two threads.
TEST(ThreadsTest, EveryEngineThreadFlushesDenormals) {
#if !defined(__SSE2__)
  GTEST_SKIP() << "no x86 flush-to-zero control on this CPU";
#endif
  set_threads(2);
  std::vector<float> underflow(2, -1.0f), denormal_in(2, -1.0f);
#pragma omp parallel num_threads(2)
  {
    volatile float tiny = 1e-30f, scale = 1e-10f, denormal = 1e-40f, one = 1.0f;
    const int t = omp_get_thread_num();
    underflow[t] = tiny * scale;  // 1e-40: a denormal without FTZ
    denormal_in[t] = denormal * one;
  }
  set_threads(1);
  for (int t = 0; t < 2; ++t) {
    EXPECT_EQ(underflow[t], 0.0f) << "thread " << t;
    EXPECT_EQ(denormal_in[t], 0.0f) << "thread " << t;
  }
}

TEST(ThreadsTest, TwoThreadsAgreeWithOne) {
  // Large enough that im2col, the GEMMs and the norms take their parallel paths.
  const std::vector<float> one = conv_model_grads(1);
  const std::vector<float> two = conv_model_grads(2);
  ASSERT_EQ(one.size(), two.size());
  for (std::size_t i = 0; i < one.size(); ++i)
    ASSERT_NEAR(one[i], two[i], 1e-4f * std::fabs(one[i]) + 1e-6f) << "value " << i;
  // One thread is bitwise reproducible.
  const std::vector<float> again = conv_model_grads(1);
  EXPECT_EQ(std::memcmp(one.data(), again.data(), one.size() * sizeof(float)), 0);
}

// Four losses over three models: `enc` (conv, LayerNorm) reached by losses 0 and 3, `mlp` by
// loss 1 (through a stop-gradient of `enc`'s output), `head` and a leaf `x` (through a slice, a
// view) by loss 2. Returns every parameter's and the leaf's gradient after one backward of the
// four losses at once (`parts`) or of their sum.
// The three models of the tests of several losses, each in the group given (one group may
// hold all three), and their inputs.
struct ThreeModels {
  ThreeModels(ParamGroup& enc_group, ParamGroup& mlp_group, ParamGroup& head_group, Rng& rng)
      : enc(enc_group, "enc", {.image = 16, .channels = 3, .depth = 4, .min_res = 4}, rng),
        mlp(mlp_group, "mlp", enc.embed_dim(), {.units = 32, .layers = 2, .out = 4}, rng),
        head(head_group, "head", 16, 5, {}, rng) {
    for (float& v : images) v = rng.uniform();
    for (float& v : xs) v = rng.normal();
  }
  ConvEncoder enc;
  Mlp mlp;
  Linear head;
  std::vector<float> images = std::vector<float>(8 * 16 * 16 * 3), xs = std::vector<float>(6 * 16);
};

std::vector<float> several_losses_grads(bool parts, int threads) {
  set_threads(threads);
  Rng rng(22);
  ParamGroup group("m");
  ThreeModels models(group, group, group, rng);
  auto& [enc, mlp, head, images, xs] = models;
  Graph& g = current_graph();
  g.reset();
  const Tensor embed = enc(constant({8, 16, 16, 3}, images));
  const Tensor x = grad_leaf({6, 16}, xs);
  const std::vector<Tensor> losses = {
      mean(square(embed)), mean(square(mlp(stop_gradient(embed)))),
      mean(square(head(slice(x, 1, 5, 0)))),
      mean(enc(constant({8, 16, 16, 3}, std::vector<float>(images.rbegin(), images.rend()))))};
  if (parts)
    EXPECT_EQ(g.backward(losses), 3);
  else
    g.backward(add(add(losses[0], losses[1]), add(losses[2], losses[3])));
  // The leaf's gradient lives in this graph, not in a helper thread's scratch: scratch work on
  // every thread's graph afterwards leaves it alone.
  parallel_tasks(
      4, [](std::int64_t) { std::fill_n(current_graph().alloc(1 << 16), 1 << 16, std::nanf("")); });
  std::vector<float> out(x.grad(), x.grad() + x.numel());
  for (const auto& p : group.params()) {
    out.insert(out.end(), p->grad().begin(), p->grad().end());
    EXPECT_EQ(p->tensor().node()->reached_by, 0u) << p->name() << " kept its loss bits";
  }
  g.reset();
  set_threads(1);
  return out;
}

// The parts of one backward ({0, 3}, {1}, {2}) run on two threads at once and give bitwise the
// gradients of one backward of the losses' sum.
TEST(ThreadsTest, BackwardOfSeveralLossesGivesTheGradientsOfTheirSum) {
  const std::vector<float> sum_one = several_losses_grads(false, 1);
  const std::vector<float> parts_one = several_losses_grads(true, 1);
  const std::vector<float> parts_two = several_losses_grads(true, 2);
  ASSERT_EQ(sum_one.size(), parts_two.size());
  EXPECT_GT(std::count_if(sum_one.begin(), sum_one.end(), [](float v) { return v != 0.0f; }),
            static_cast<std::ptrdiff_t>(sum_one.size() * 9 / 10));
  for (std::size_t i = 0; i < sum_one.size(); ++i) {
    ASSERT_EQ(sum_one[i], parts_one[i]) << "value " << i << ", one thread";
    ASSERT_EQ(sum_one[i], parts_two[i]) << "value " << i << ", two threads";
  }
}

std::vector<float> grads_of(const ParamGroup& group) {
  std::vector<float> out;
  for (const auto& p : group.params()) {
    const std::span<const float> g = std::as_const(*p).grad();
    out.insert(out.end(), g.begin(), g.end());
  }
  return out;
}

// after(i) of a backward of several losses runs once per loss, when the gradients of i's part
// are complete (they are already those of the whole backward), without recording; what it does
// to its own part's gradients (here: an optimiser's zeroing) leaves the other parts alone. A
// loss that reaches no parameter gets its call on the calling thread.
TEST(ThreadsTest, AfterEachPartSeesItsGradientsComplete) {
  for (const int threads : {1, 2}) {
    SCOPED_TRACE(testing::Message() << threads << " threads");
    Rng rng(23);
    ParamGroup enc_group("enc"), mlp_group("mlp"), head_group("head");
    ThreeModels models(enc_group, mlp_group, head_group, rng);
    auto& [enc, mlp, head, images, xs] = models;
    // Losses 0 and 3 reach `enc`, 1 `mlp`, 2 `head`, 4 nothing. `parts`: backward of the five at
    // once, else of their sum; returns the final gradients of enc, mlp and head.
    std::vector<std::vector<float>> seen(5);  // in after(i): the gradients of i's part
    std::vector<std::thread::id> thread_of(5);
    std::vector<int> calls(5, 0), recording(5, -1);
    const auto run = [&](bool parts) {
      set_threads(parts ? threads : 1);
      Graph& g = current_graph();
      g.reset();
      const Tensor embed = enc(constant({8, 16, 16, 3}, images));
      const Tensor x = constant({6, 16}, xs);
      const std::vector<Tensor> losses = {
          mean(square(embed)), mean(square(mlp(stop_gradient(embed)))), mean(square(head(x))),
          mean(enc(constant({8, 16, 16, 3}, std::vector<float>(images.rbegin(), images.rend())))),
          mean(square(x))};
      if (parts) {
        const ParamGroup* group_of[5] = {&enc_group, &mlp_group, &head_group, &enc_group, nullptr};
        EXPECT_EQ(g.backward(losses,
                             [&](int i) {
                               ++calls[i];
                               thread_of[i] = std::this_thread::get_id();
                               recording[i] = current_graph().grad_enabled();
                               if (group_of[i] != nullptr) seen[i] = grads_of(*group_of[i]);
                               if (i == 1) mlp_group.zero_grad();
                             }),
                  3);
      } else {
        g.backward(add(add(add(losses[0], losses[1]), add(losses[2], losses[3])), losses[4]));
      }
      std::vector<std::vector<float>> out = {grads_of(enc_group), grads_of(mlp_group),
                                             grads_of(head_group)};
      for (ParamGroup* group : {&enc_group, &mlp_group, &head_group}) group->zero_grad();
      g.reset();
      set_threads(1);
      return out;
    };
    const std::vector<std::vector<float>> sum = run(false);
    const std::vector<std::vector<float>> parts = run(true);
    for (int i = 0; i < 5; ++i) {
      EXPECT_EQ(calls[i], 1) << "loss " << i;
      EXPECT_EQ(recording[i], 0) << "loss " << i;
    }
    EXPECT_EQ(thread_of[4], std::this_thread::get_id());
    EXPECT_EQ(thread_of[0], thread_of[3]) << "losses of one part were handed to two threads";
    ASSERT_FALSE(sum[0].empty());
    EXPECT_EQ(seen[0], sum[0]);
    EXPECT_EQ(seen[3], sum[0]);
    EXPECT_EQ(seen[1], sum[1]);
    EXPECT_EQ(seen[2], sum[2]);
    // The final gradients: every part's as with one backward, except what after(1) zeroed.
    EXPECT_EQ(parts[0], sum[0]);
    EXPECT_EQ(parts[2], sum[2]);
    EXPECT_TRUE(std::all_of(parts[1].begin(), parts[1].end(), [](float v) { return v == 0; }));
    EXPECT_TRUE(std::any_of(sum[1].begin(), sum[1].end(), [](float v) { return v != 0; }));
  }
}

// Tasks run once each, spread over the threads, each on its own thread's graph: they read the
// caller's tensors, and the caller's graph is as it was. An exception reaches the caller.
TEST(ThreadsTest, ParallelTasksRunOnceEachOnTheirThreadsOwnGraph) {
  Graph& g = current_graph();
  g.reset();
  const Tensor input = full({1000}, 3.0f);
  const std::size_t used = g.arena_used_bytes();
  set_threads(2);
  std::vector<float> out(16, 0.0f);
  std::vector<const Graph*> graphs(16, nullptr);
  std::vector<std::thread::id> threads(16);
  std::vector<int> recording(16, -1);
  parallel_tasks(16, [&](std::int64_t i) {
    graphs[i] = &current_graph();
    threads[i] = std::this_thread::get_id();
    recording[i] = current_graph().grad_enabled();
    out[i] += sum(scale(input, static_cast<float>(i))).item();
  });
  // Each task ran without recording, and what it allocated was given back.
  for (int i = 0; i < 16; ++i) EXPECT_EQ(recording[i], 0) << "task " << i;
  for (int i = 0; i < 16; ++i) EXPECT_EQ(out[i], 3000.0f * i) << "task " << i;
  EXPECT_EQ(g.arena_used_bytes(), used);
  EXPECT_TRUE(g.grad_enabled());
  // Every task ran on its thread's own graph: one graph per thread, none shared by two
  // threads, the calling thread's being `g`, and no more threads than were set.
  std::map<std::thread::id, const Graph*> graph_of;
  std::set<const Graph*> distinct;
  for (int i = 0; i < 16; ++i) {
    ASSERT_NE(graphs[i], nullptr) << "task " << i;
    const auto [it, first] = graph_of.emplace(threads[i], graphs[i]);
    EXPECT_EQ(it->second, graphs[i]) << "task " << i << " ran on another graph of its thread";
    distinct.insert(graphs[i]);
  }
  EXPECT_EQ(distinct.size(), graph_of.size()) << "two threads shared a graph";
  EXPECT_LE(graph_of.size(), 2u);
  if (const auto it = graph_of.find(std::this_thread::get_id()); it != graph_of.end()) {
    EXPECT_EQ(it->second, &g);
  }
  // Task `failing` allocates and then throws; the others only allocate.
  const auto tasks_failing_at = [&](std::int64_t failing) {
    return [&input, failing](std::int64_t i) {
      const Tensor scratch = scale(input, 2.0f);
      if (i == failing && scratch.numel() == 1000) throw std::runtime_error("task failed");
    };
  };
  EXPECT_THROW(parallel_tasks(8, tasks_failing_at(5)), std::runtime_error);
  EXPECT_EQ(g.arena_used_bytes(), used) << "a task that threw kept its allocations";
  set_threads(1);
  int ran = 0;
  parallel_tasks(3, [&](std::int64_t) { ++ran; });  // one thread: in order on the caller
  EXPECT_EQ(ran, 3);
  EXPECT_THROW(parallel_tasks(3, tasks_failing_at(1)), std::runtime_error);
  EXPECT_EQ(g.arena_used_bytes(), used) << "a task that threw on the caller kept its allocations";
  EXPECT_TRUE(g.grad_enabled());
}

TEST(RngTest, DeterministicAndRoughlyNormal) {
  Rng a(42), b(42), c(43);
  EXPECT_EQ(a.next_u64(), b.next_u64());
  EXPECT_NE(a.next_u64(), c.next_u64());
  Rng r(7);
  double mean = 0, var = 0;
  const int n = 100000;
  for (int i = 0; i < n; ++i) {
    const double z = r.normal();
    mean += z / n;
    var += z * z / n;
  }
  EXPECT_NEAR(mean, 0.0, 0.02);
  EXPECT_NEAR(var, 1.0, 0.02);
  for (int i = 0; i < 1000; ++i) {
    const float u = r.uniform();
    EXPECT_GE(u, 0.0f);
    EXPECT_LT(u, 1.0f);
    EXPECT_LT(r.below(9), 9);
  }
}

}  // namespace
}  // namespace indrive::nn
