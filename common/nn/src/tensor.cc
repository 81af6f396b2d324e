// Shapes, the arena-backed graph with its backward pass, parameters, groups, the RNG and the
// thread setting.
#include "indrive/nn/tensor.h"

#include <omp.h>
#if defined(__SSE2__)
#include <xmmintrin.h>
#endif
#include <sys/mman.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <mutex>
#include <sstream>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "indrive/basics/check.h"
#include "indrive/nn/kernels.h"

namespace indrive::nn {

// ---- Shape ----

Shape::Shape(std::initializer_list<std::int64_t> d) {
  INDRIVE_CHECK_LE(static_cast<int>(d.size()), kMaxRank) << "tensors have at most 4 dimensions";
  rank = static_cast<int>(d.size());
  int i = 0;
  for (std::int64_t v : d) {
    INDRIVE_CHECK(v > 0) << "dimension " << i << " is " << v;
    dims[i++] = v;
  }
}

std::int64_t Shape::operator[](int i) const {
  if (i < 0) i += rank;
  INDRIVE_CHECK(i >= 0 && i < rank) << "axis out of range for shape " << str();
  return dims[i];
}

std::int64_t Shape::numel() const {
  std::int64_t n = 1;
  for (int i = 0; i < rank; ++i) n *= dims[i];
  return n;
}

std::string Shape::str() const {
  std::ostringstream out;
  out << "(";
  for (int i = 0; i < rank; ++i) out << (i ? ", " : "") << dims[i];
  out << ")";
  return out.str();
}

bool Shape::operator==(const Shape& other) const {
  if (rank != other.rank) return false;
  for (int i = 0; i < rank; ++i)
    if (dims[i] != other.dims[i]) return false;
  return true;
}

// ---- Tensor ----

float Tensor::item() const {
  INDRIVE_CHECK_EQ(numel(), 1) << "item() needs a one-element tensor, shape " << shape().str();
  return node_->value[0];
}

// ---- Graph ----

namespace {
constexpr std::size_t kAlign = 64;
constexpr std::size_t kMinBlock = std::size_t{16} << 20;
// Blocks are aligned to and sized in 2 MiB units so that the kernel can back them with huge
// pages: a training step writes hundreds of MiB of fresh activations, and small pages would
// cost one fault (and one TLB entry) per 4 KiB.
constexpr std::size_t kHugePage = std::size_t{2} << 20;

std::size_t round_up(std::size_t n, std::size_t to = kAlign) { return (n + to - 1) / to * to; }

std::byte* system_alloc(std::size_t bytes) {
  void* p = std::aligned_alloc(kHugePage, bytes);
  INDRIVE_CHECK(p != nullptr) << "out of memory: the graph arena needs " << (bytes >> 20)
                              << " MiB more";
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  madvise(p, bytes, MADV_HUGEPAGE);  // advice only: failure just means small pages
#endif
  return static_cast<std::byte*>(p);
}

// Eigen's GEMM mallocs its packing buffers (about 1 MiB) on every product, on whichever thread
// runs it. With the default policy glibc hands such sizes back to the system on free (munmap,
// or trimming the top of a thread's heap), so every product faults its buffers in again. Keep
// freed memory in the process instead: the buffers are then recycled.
void keep_freed_memory() {
#if defined(__GLIBC__)
  static const bool once = [] {
    mallopt(M_MMAP_THRESHOLD, 64 << 20);
    mallopt(M_TRIM_THRESHOLD, 512 << 20);
    return true;
  }();
  (void)once;
#endif
}
}  // namespace

Graph::Graph() {
  keep_freed_memory();
  tape_.reserve(4096);
}
Graph::~Graph() { free_blocks(); }

void Graph::free_blocks() {
  for (Block& b : blocks_) std::free(b.memory);
  blocks_.clear();
  current_ = 0;
}

void* Graph::alloc_bytes(std::size_t bytes) {
  if (shared_) {
    const std::lock_guard<std::mutex> lock(shared_mutex_);
    return alloc_bytes_unlocked(bytes);
  }
  return alloc_bytes_unlocked(bytes);
}

void* Graph::alloc_bytes_unlocked(std::size_t bytes) {
  bytes = round_up(std::max<std::size_t>(bytes, 1));
  // Move on through the kept blocks until one has room; a step that repeats the previous one
  // walks the same blocks with the same offsets.
  while (current_ < blocks_.size() && blocks_[current_].used + bytes > blocks_[current_].size)
    ++current_;
  if (current_ == blocks_.size()) {
    // Grow geometrically (each new block at least as large as all before it), so a step of
    // any size needs few blocks.
    Block block;
    block.size = round_up(std::max({bytes, kMinBlock, arena_capacity_bytes()}), kHugePage);
    block.memory = system_alloc(block.size);
    ++system_allocations_;
    blocks_.push_back(block);
  }
  Block& b = blocks_[current_];
  void* p = b.memory + b.used;
  b.used += bytes;
  return p;
}

float* Graph::alloc(std::int64_t n) {
  return static_cast<float*>(alloc_bytes(static_cast<std::size_t>(n) * sizeof(float)));
}

float* Graph::alloc_zeroed(std::int64_t n) {
  float* p = alloc(n);
  std::memset(p, 0, static_cast<std::size_t>(n) * sizeof(float));
  return p;
}

std::size_t Graph::arena_used_bytes() const {
  std::size_t used = 0;
  for (const Block& b : blocks_) used += b.used;
  return used;
}

std::size_t Graph::arena_capacity_bytes() const {
  std::size_t size = 0;
  for (const Block& b : blocks_) size += b.size;
  return size;
}

void Graph::reset() {
  detail::forget_graph_conversions(true);
  high_water_ = std::max(high_water_, arena_used_bytes());
  for (Block& b : blocks_) b.used = 0;
  current_ = 0;
  tape_.clear();
  num_nodes_ = 0;
}

Graph::Mark Graph::mark() const {
  Mark m;
  m.block = current_;
  m.used = current_ < blocks_.size() ? blocks_[current_].used : 0;
  m.nodes = num_nodes_;
  m.tape = tape_.size();
  return m;
}

void Graph::rewind(const Mark& mark) {
  detail::forget_graph_conversions(false);
  INDRIVE_CHECK_EQ(tape_.size(), mark.tape)
      << "rewind() past recorded ops: only scratch work under NoGradGuard can be rewound";
  INDRIVE_CHECK(mark.block <= current_ && num_nodes_ >= mark.nodes)
      << "rewind() to a mark taken after a reset or a later mark";
  high_water_ = std::max(high_water_, arena_used_bytes());
  for (std::size_t i = mark.block; i < blocks_.size(); ++i) blocks_[i].used = 0;
  if (mark.block < blocks_.size()) blocks_[mark.block].used = mark.used;
  current_ = mark.block;
  num_nodes_ = mark.nodes;
}

void Graph::release_memory() {
  reset();
  free_blocks();
  high_water_ = 0;
}

detail::Node* Graph::new_view_node(const Shape& shape, float* value) {
  auto* node = new (alloc_bytes(sizeof(detail::Node))) detail::Node();
  node->shape = shape;
  node->value = value;
  ++num_nodes_;
  return node;
}

detail::Node* Graph::new_node(const Shape& shape) {
  return new_view_node(shape, alloc(shape.numel()));
}

void Graph::link_view(detail::Node* view, detail::Node* source, std::int64_t offset) {
  if (!grad_enabled_ || !source->requires_grad) return;
  view->requires_grad = true;
  view->view_of = source;
  view->view_offset = offset;
}

float* Graph::grad_buffer(detail::Node* node) {
  if (node == nullptr || !node->requires_grad) return nullptr;
  if (node->grad == nullptr) {
    if (node->view_of != nullptr)
      node->grad = grad_buffer(node->view_of) + node->view_offset;
    else
      node->grad = alloc_zeroed(node->shape.numel());
  }
  return node->grad;
}

float* Graph::grad_buffer_for_write(detail::Node* node, bool* fresh) {
  *fresh = false;
  if (node == nullptr || !node->requires_grad) return nullptr;
  if (node->grad == nullptr && node->view_of == nullptr) {
    // Nothing has been added to this gradient yet (views allocate their source's buffer
    // when first used), so the first writer may overwrite instead of accumulate.
    node->grad = alloc(node->shape.numel());
    *fresh = true;
    return node->grad;
  }
  return grad_buffer(node);
}

void Graph::record(detail::Node* node, detail::BackwardFn fn,
                   std::initializer_list<detail::Node*> in) {
  INDRIVE_CHECK_LE(static_cast<int>(in.size()), 3) << "ops have at most 3 inputs";
  int i = 0;
  bool needs = false;
  for (detail::Node* n : in) {
    node->in[i++] = n;
    if (n != nullptr && n->requires_grad) needs = true;
  }
  if (!grad_enabled_ || !needs) return;
  node->requires_grad = true;
  node->backward = fn;
  tape_.push_back(node);
}

void Graph::backward(Tensor loss) {
  INDRIVE_CHECK(loss.defined()) << "backward() of an undefined tensor";
  INDRIVE_CHECK_EQ(loss.numel(), 1)
      << "backward() needs a scalar loss, got shape " << loss.shape().str();
  detail::Node* root = loss.node();
  if (!root->requires_grad) return;  // nothing depends on a parameter
  grad_buffer(root)[0] += 1.0f;
  // Nodes were recorded in creation order, which is a topological order of the graph.
  for (auto it = tape_.rbegin(); it != tape_.rend(); ++it) {
    detail::Node* node = *it;
    if (node->grad == nullptr) continue;  // no gradient reached this node
    node->backward(*node);
  }
}

namespace {

// Set on a thread while it runs a part of another graph's backward.
thread_local Graph* t_gradient_graph = nullptr;

// Runs fn(i) for every i in [0, n) on `workers` OpenMP threads, one i at a time each; the first
// exception fn throws is rethrown once all have run.
void run_on_threads(std::int64_t n, int workers, const std::function<void(std::int64_t)>& fn) {
  std::exception_ptr error;
  std::mutex error_mutex;
#pragma omp parallel for schedule(dynamic, 1) num_threads(workers)
  for (std::int64_t i = 0; i < n; ++i) {
    try {
      fn(i);
    } catch (...) {
      const std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
    }
  }
  if (error) std::rethrow_exception(error);
}

// Union-find over the (at most 32) losses of one backward.
struct LossSets {
  int parent[32];
  explicit LossSets(int n) {
    for (int i = 0; i < n; ++i) parent[i] = i;
  }
  int find(int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  }
  // Joins every loss whose bit is set in `bits`.
  void join(std::uint32_t bits) {
    const int first = std::countr_zero(bits);
    for (bits &= bits - 1; bits != 0; bits &= bits - 1) {
      const int a = find(first), b = find(std::countr_zero(bits));
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  }
};

}  // namespace

void Graph::run_backward_part(const std::vector<detail::Node*>& nodes, std::uint32_t losses,
                              const std::function<void(int)>& after) {
  for (detail::Node* node : nodes)
    if (node->grad != nullptr) node->backward(*node);
  if (!after) return;
  NoGradGuard no_grad;
  for (; losses != 0; losses &= losses - 1) after(std::countr_zero(losses));
}

int Graph::backward(std::span<const Tensor> losses, const std::function<void(int)>& after) {
  INDRIVE_CHECK(!losses.empty()) << "backward() of no losses";
  INDRIVE_CHECK_LE(losses.size(), 32u) << "backward() of more than 32 losses at once";
  const int n = static_cast<int>(losses.size());
  for (const Tensor& loss : losses) {
    INDRIVE_CHECK(loss.defined()) << "backward() of an undefined tensor";
    INDRIVE_CHECK_EQ(loss.numel(), 1)
        << "backward() needs scalar losses, got shape " << loss.shape().str();
  }
  // Which losses reach each node: tape order is topological, so one pass in reverse carries
  // every loss's bit from a node to its inputs (and from a view to the tensor it views).
  LossSets sets(n);
  std::vector<detail::Node*> persistent;  // parameters reached, whose bits outlive the step
  auto reach = [&](detail::Node* node, std::uint32_t bits) {
    for (; node != nullptr && node->requires_grad; node = node->view_of) {
      if (node->reached_by == 0 && node->persistent) persistent.push_back(node);
      if ((node->reached_by | bits) == node->reached_by) return;
      node->reached_by |= bits;
      if (std::popcount(node->reached_by) > 1) sets.join(node->reached_by);
    }
  };
  for (int i = 0; i < n; ++i) reach(losses[i].node(), std::uint32_t{1} << i);
  for (auto it = tape_.rbegin(); it != tape_.rend(); ++it) {
    const std::uint32_t bits = (*it)->reached_by;
    if (bits == 0) continue;
    for (detail::Node* in : (*it)->in) reach(in, bits);
  }
  // One list of nodes per part, each in reverse creation order, and the part's losses.
  struct Part {
    std::vector<detail::Node*> nodes;
    std::uint32_t losses = 0;
  };
  std::vector<Part> parts(static_cast<std::size_t>(n));
  for (auto it = tape_.rbegin(); it != tape_.rend(); ++it) {
    const std::uint32_t bits = (*it)->reached_by;
    if (bits != 0) parts[sets.find(std::countr_zero(bits))].nodes.push_back(*it);
  }
  for (detail::Node* p : persistent) p->reached_by = 0;
  for (int i = 0; i < n; ++i) parts[sets.find(i)].losses |= std::uint32_t{1} << i;
  // A loss that reaches no parameter has no part; its after() runs on this thread at the end.
  std::uint32_t without_part = 0;
  for (const Part& p : parts)
    if (p.nodes.empty()) without_part |= p.losses;
  std::erase_if(parts, [](const Part& p) { return p.nodes.empty(); });
  for (const Tensor& loss : losses)
    if (loss.node()->requires_grad) grad_buffer(loss.node())[0] += 1.0f;

  const int workers = omp_in_parallel() ? 1
                                        : static_cast<int>(std::min<std::size_t>(
                                              static_cast<std::size_t>(threads()), parts.size()));
  const int count = static_cast<int>(parts.size());
  if (workers <= 1) {
    for (const Part& part : parts) run_backward_part(part.nodes, part.losses, after);
  } else {
    // Largest part first, so that the others fill in beside it.
    std::stable_sort(parts.begin(), parts.end(),
                     [](const Part& a, const Part& b) { return a.nodes.size() > b.nodes.size(); });
    shared_ = true;
    try {
      run_on_threads(count, workers, [&](std::int64_t i) {
        // A helper thread puts gradients into this graph and its scratch into its own, which it
        // gives back afterwards.
        Graph& here = current_graph();
        const bool helper = &here != this;
        const Mark mark = here.mark();
        const auto done = [&] {
          t_gradient_graph = nullptr;
          if (helper) here.rewind(mark);
        };
        t_gradient_graph = this;
        try {
          NoGradGuard no_grad;
          const Part& part = parts[static_cast<std::size_t>(i)];
          run_backward_part(part.nodes, part.losses, after);
        } catch (...) {
          done();
          throw;
        }
        done();
      });
    } catch (...) {
      shared_ = false;
      throw;
    }
    shared_ = false;
  }
  if (after) {
    NoGradGuard no_grad;
    for (; without_part != 0; without_part &= without_part - 1)
      after(std::countr_zero(without_part));
  }
  return count;
}

Graph& current_graph() {
  thread_local Graph graph;
  return graph;
}

Graph& gradient_graph() {
  return t_gradient_graph != nullptr ? *t_gradient_graph : current_graph();
}

NoGradGuard::NoGradGuard() : previous_(current_graph().grad_enabled_) {
  current_graph().grad_enabled_ = false;
}
NoGradGuard::~NoGradGuard() { current_graph().grad_enabled_ = previous_; }

// ---- Creation ----

Tensor empty(const Shape& shape) { return Tensor(current_graph().new_node(shape)); }

Tensor zeros(const Shape& shape) { return full(shape, 0.0f); }

Tensor full(const Shape& shape, float value) {
  Tensor t = empty(shape);
  std::fill_n(t.data(), t.numel(), value);
  return t;
}

Tensor constant(const Shape& shape, std::span<const float> values) {
  INDRIVE_CHECK_EQ(static_cast<std::int64_t>(values.size()), shape.numel())
      << "constant() of shape " << shape.str();
  Tensor t = empty(shape);
  std::copy(values.begin(), values.end(), t.data());
  return t;
}

Tensor grad_leaf(const Shape& shape, std::span<const float> values) {
  Tensor t = constant(shape, values);
  t.node()->requires_grad = true;
  return t;
}

// ---- Parameters ----

Parameter::Parameter(std::string name, const Shape& shape)
    : name_(std::move(name)),
      value_(static_cast<std::size_t>(shape.numel()), 0.0f),
      grad_(static_cast<std::size_t>(shape.numel()), 0.0f) {
  node_.shape = shape;
  node_.value = value_.data();
  node_.grad = grad_.data();
  node_.requires_grad = true;
  node_.persistent = true;
  node_.version = detail::next_parameter_version();
}

void Parameter::zero_grad() { std::fill(grad_.begin(), grad_.end(), 0.0f); }

ParamGroup::ParamGroup(std::string name) : name_(std::move(name)) {}

Parameter& ParamGroup::add(const std::string& name, const Shape& shape) {
  INDRIVE_CHECK(find(name) == nullptr)
      << "parameter '" << name << "' already in group '" << name_ << "'";
  params_.push_back(std::make_unique<Parameter>(name, shape));
  return *params_.back();
}

Parameter* ParamGroup::find(const std::string& name) const {
  for (const auto& p : params_)
    if (p->name() == name) return p.get();
  return nullptr;
}

std::int64_t ParamGroup::numel() const {
  std::int64_t n = 0;
  for (const auto& p : params_) n += p->numel();
  return n;
}

void ParamGroup::zero_grad() {
  for (auto& p : params_) p->zero_grad();
}

// ---- Rng ----

namespace {
std::uint64_t splitmix64(std::uint64_t& x) {
  std::uint64_t z = (x += 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}
std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
}  // namespace

Rng::Rng(std::uint64_t seed) {
  for (auto& s : s_) s = splitmix64(seed);
}

std::uint64_t Rng::next_u64() {
  const std::uint64_t result = rotl(s_[1] * 5, 7) * 9;
  const std::uint64_t t = s_[1] << 17;
  s_[2] ^= s_[0];
  s_[3] ^= s_[1];
  s_[1] ^= s_[2];
  s_[0] ^= s_[3];
  s_[2] ^= t;
  s_[3] = rotl(s_[3], 45);
  return result;
}

float Rng::uniform() { return static_cast<float>(next_u64() >> 40) * (1.0f / 16777216.0f); }

float Rng::normal() {
  // Box-Muller with u1 in (0, 1] so the log is finite.
  const double u1 = (static_cast<double>(next_u64() >> 11) + 1.0) * (1.0 / 9007199254740992.0);
  const double u2 = static_cast<double>(next_u64() >> 11) * (1.0 / 9007199254740992.0);
  return static_cast<float>(std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2));
}

std::int64_t Rng::below(std::int64_t n) {
  INDRIVE_CHECK(n > 0) << "below(" << n << ")";
  return static_cast<std::int64_t>(next_u64() % static_cast<std::uint64_t>(n));
}

// ---- Threads ----

namespace {
int g_threads = 0;
}

void set_threads(int threads) {
  INDRIVE_CHECK(threads >= 1) << "threads must be >= 1, got " << threads;
  g_threads = threads;
  omp_set_num_threads(threads);
  // Eigen's own GEMM threading stays off: the engine splits large products itself.
  Eigen::setNbThreads(1);
  flush_denormals();
}

bool flush_denormals() {
#if defined(__SSE2__)
  // MXCSR bit 15 (flush to zero) and bit 6 (denormals are zero). The register is per thread,
  // and OpenMP keeps its threads between parallel regions, so setting it once in a region of
  // the engine's thread count reaches every thread that runs an op.
  const auto set = [] { _mm_setcsr(_mm_getcsr() | 0x8040u); };
  set();
  if (!omp_in_parallel()) {
#pragma omp parallel num_threads(threads())
    set();
  }
  return true;
#else
  return false;
#endif
}

int threads() { return g_threads > 0 ? g_threads : omp_get_max_threads(); }

namespace {

// Task i on the calling thread's graph, recording nothing; whatever it allocated there is given
// back after it, also when it throws.
void run_scratch_task(const std::function<void(std::int64_t)>& task, std::int64_t i) {
  Graph& graph = current_graph();
  const Graph::Mark mark = graph.mark();
  try {
    NoGradGuard no_grad;
    task(i);
  } catch (...) {
    graph.rewind(mark);
    throw;
  }
  graph.rewind(mark);
}

}  // namespace

void parallel_tasks(std::int64_t n, const std::function<void(std::int64_t)>& task) {
  const int workers =
      omp_in_parallel() ? 1 : static_cast<int>(std::min<std::int64_t>(omp_get_max_threads(), n));
  if (workers <= 1) {
    for (std::int64_t i = 0; i < n; ++i) run_scratch_task(task, i);
    return;
  }
  run_on_threads(n, workers, [&task](std::int64_t i) { run_scratch_task(task, i); });
}

}  // namespace indrive::nn
